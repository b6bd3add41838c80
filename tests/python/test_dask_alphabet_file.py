"""The alphabet file a lex3d-dask job is given (--alphabet): compress and place build read it
through one function, so both say the same: a file that cannot be read is an I/O error (exit 3),
one that reads but does not decode is bad data (exit 2). The errors come before any work, with
one line naming the file and nothing written. Run by ctest (python.tests)."""

import os
import pathlib
import subprocess
import sys

import pytest

import lex3d

pytest.importorskip("distributed")
import lex3d.dask  # noqa: E402
from lex3d.dask._files import read_alphabet_file  # noqa: E402

SAMPLES = pathlib.Path(os.environ.get("LEX3D_SAMPLES", pathlib.Path(__file__).parents[2] / "samples"))
SCAN = str(SAMPLES / "kitti00_000000.bin")
GOLDEN = pathlib.Path(__file__).parents[1] / "codec" / "golden" / "tiny_alphabet_1.0.lex3da"


def lex3d_dask(*args):
    """The lex3d-dask command as installed (LEX3D_DASK, set by ctest), else python3 -m lex3d.dask."""
    exe = os.environ.get("LEX3D_DASK")
    cmd = [exe] if exe else [sys.executable, "-m", "lex3d.dask"]
    return subprocess.run(cmd + list(args), capture_output=True, text=True, env=dict(os.environ), timeout=300)


@pytest.fixture()
def bad_alphabets(tmp_path):
    """(path, exit code, text of the error): a missing file and a damaged one."""
    damaged = bytearray(GOLDEN.read_bytes())
    damaged[len(damaged) // 2] ^= 0x40  # a byte inside a chunk: its CRC no longer matches
    (tmp_path / "damaged.lex3da").write_bytes(bytes(damaged))
    return [(tmp_path / "missing.lex3da", 3, "cannot read the alphabet: No such file or directory"),
            (tmp_path / "damaged.lex3da", 2, "CRC")]


def test_one_reader_for_both_exit_codes(tmp_path):
    good = GOLDEN.read_bytes()
    assert read_alphabet_file(GOLDEN) == good
    (tmp_path / "empty.lex3da").write_bytes(b"")
    (tmp_path / "short.lex3da").write_bytes(good[:40])
    for path, code in ((tmp_path / "missing.lex3da", 3), (tmp_path, 3),  # a folder does not read
                       (tmp_path / "empty.lex3da", 2), (tmp_path / "short.lex3da", 2), (SCAN, 2)):
        with pytest.raises(lex3d.dask.CompressError) as e:
            read_alphabet_file(path)
        assert e.value.code == code, (path, str(e.value))
        assert str(e.value).startswith(f"{path}: ") and "\n" not in str(e.value)


@pytest.mark.parametrize("command", ["compress", "place build"])
def test_the_command_names_the_alphabet_with_its_exit_code(client, tmp_path, bad_alphabets, command):
    out = tmp_path / ("s.lex3dm" if command == "compress" else "db")
    before = sorted(tmp_path.iterdir())
    for path, code, text in bad_alphabets:
        args = command.split() + [SCAN, "-o", str(out),
                                  "--alphabet", str(path), "--scheduler", client.scheduler.address]
        if command == "place build":
            args += ["--shards", "1"]
        else:
            args += ["--words", "on"]
        r = lex3d_dask(*args)
        assert r.returncode == code, (path, r.stderr)
        lines = r.stderr.strip().splitlines()
        assert len(lines) == 1 and lines[0].startswith(f"lex3d-dask: {path}: ") and text in lines[0], r.stderr
        assert sorted(tmp_path.iterdir()) == before  # nothing written: no output, manifest or folder
