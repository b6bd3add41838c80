"""lex3d.dask on a real LocalCluster (a scheduler and 2 worker processes on loopback): the
files are byte for byte those of `lex3d compress SCANS --alphabet A -o OUT`, the manifest lists
every scan, a bad scan in the middle is named while the others complete, a worker killed mid-job
loses nothing, and the command's exit codes. Run by ctest (python.tests)."""

import json
import os
import pathlib
import subprocess
import sys

import pytest

import lex3d

distributed = pytest.importorskip("distributed")
import lex3d.dask  # noqa: E402
from conftest import compress_killing_a_worker  # noqa: E402

SAMPLES = pathlib.Path(os.environ.get("LEX3D_SAMPLES", pathlib.Path(__file__).parents[2] / "samples"))
CLI = os.environ.get("LEX3D_CLI")
SCANS = [str(SAMPLES / "newer_college_00.bin"), str(SAMPLES / "kitti00_000000.bin"), str(SAMPLES / "room_scan1.pcd")]


def manifest_rows(path):
    lines = pathlib.Path(path).read_text().splitlines()
    return json.loads(lines[0]), [json.loads(line) for line in lines[1:]]


def no_temporaries(folder):
    return [p.name for p in pathlib.Path(folder).iterdir() if p.name.endswith(".tmp")] == []


@pytest.mark.skipif(not CLI, reason="LEX3D_CLI not set (run through ctest)")
@pytest.mark.parametrize("options, cli_args", [
    ({"iterations": 40}, ["--max-error", "none"]),
    ({"max_error": 0.02}, ["--max-error", "0.02"]),
    ({"max_error": 0.02, "batch": 2}, ["--max-error", "0.02"]),  # tasks of 2 and 1 scans
    ({"max_error": 0.02, "objective": "mse"}, ["--max-error", "0.02", "--objective", "mse"]),
])
def test_same_files_as_the_command(client, tmp_path, options, cli_args):
    out = tmp_path / "dask" / "s.lex3dm"
    out.parent.mkdir()
    summary = lex3d.dask.compress(SCANS, out, client=client, learn_scans=2, **options)
    assert summary["ok"] == 3 and summary["failed"] == 0 and summary["workers"] == 2
    ref = tmp_path / "cli" / "s.lex3dm"
    ref.parent.mkdir()
    args = [CLI, "compress", *SCANS, "-o", str(ref)] + (["--alphabet", summary["alphabet"]] if summary["alphabet"] else [])
    subprocess.run(args + cli_args, check=True, capture_output=True)
    header, rows = manifest_rows(summary["manifest"])
    assert header["scans"] == 3 and [r["index"] for r in rows] == [0, 1, 2]
    for i, row in enumerate(rows):
        produced = (tmp_path / "dask" / f"s_{i:03d}.lex3dm").read_bytes()
        assert produced == (tmp_path / "cli" / f"s_{i:03d}.lex3dm").read_bytes(), row["scan"]
        assert row["status"] == "ok" and row["file"] == str(tmp_path / "dask" / f"s_{i:03d}.lex3dm")
        assert row["bytes"] == len(produced) and row["points"] > 20000
        assert abs(row["bits_per_point"] - 8 * len(produced) / row["points"]) < 1e-9
        assert row["max_error"] == options.get("max_error")
    assert summary["alphabet"] is None or "max_error" not in options
    if options.get("batch") == 2:
        assert rows[0]["pid"] == rows[1]["pid"]  # one task coded both
    assert no_temporaries(tmp_path / "dask")


def test_a_bad_scan_in_the_middle_is_named_and_the_others_complete(client, tmp_path):
    bad = tmp_path / "broken.pcd"
    bad.write_bytes(b"# .PCD v0.7\nVERSION 0.7\nFIELDS x y z\nSIZE 4 4 4\nTYPE F F F\nCOUNT 1 1 1\n"
                    b"WIDTH 1000\nHEIGHT 1\nPOINTS 1000\nDATA binary\n" + b"\x00" * 40)
    inputs = [SCANS[0], str(bad), SCANS[0]]
    summary = lex3d.dask.compress(inputs, tmp_path / "b.lex3dm", client=client, max_error=0.03)
    assert summary["ok"] == 2 and summary["failed"] == 1
    _, rows = manifest_rows(summary["manifest"])
    assert [r["status"] for r in rows] == ["ok", "error", "ok"]
    assert "broken.pcd" in rows[1]["error"] and "\n" not in rows[1]["error"]
    assert not (tmp_path / "b_001.lex3dm").exists()
    assert (tmp_path / "b_000.lex3dm").read_bytes() == (tmp_path / "b_002.lex3dm").read_bytes()
    # (the message names the file once, as lex3d's do)
    assert rows[1]["error"].startswith(f"{bad}: ")
    assert summary["failures"] == [rows[1]["error"]]


def test_tasks_shrink_to_one_scan_as_the_work_runs_out():
    sizes, left = [], 1000
    while left:
        sizes.append(min(left, lex3d.dask._compress.batch_size(left, slots=2)))
        left -= sizes[-1]
    assert sizes[0] == 16 and sizes[-8:] == [1] * 8 and sizes == sorted(sizes, reverse=True)
    assert len(sizes) < 200  # against 1,000 one-scan tasks


def test_a_worker_killed_mid_job_loses_nothing(tmp_path):
    alphabet = lex3d.learn_alphabet([SCANS[0]], iterations=30)
    (tmp_path / "a.lex3da").write_bytes(alphabet)
    inputs = [SCANS[i % 2] for i in range(16)]
    result, done_when_killed = compress_killing_a_worker(tmp_path, lambda c: lex3d.dask.compress(
        inputs, tmp_path / "k.lex3dm", client=c, alphabet=tmp_path / "a.lex3da", window=4))
    assert done_when_killed < 16  # the kill came mid-job
    assert result["ok"] == 16 and result["failed"] == 0
    _, rows = manifest_rows(result["manifest"])
    assert [r["index"] for r in rows] == list(range(16))
    expected = {s: lex3d.compress(s, alphabet=alphabet) for s in SCANS[:2]}
    for i, row in enumerate(rows):
        assert (tmp_path / f"k_{i:03d}.lex3dm").read_bytes() == expected[inputs[i]]
        assert row["sha256"] == rows[i % 2]["sha256"]
    assert no_temporaries(tmp_path)


def run_command(*args):
    env = dict(os.environ)
    return subprocess.run([sys.executable, "-m", "lex3d.dask", *args], capture_output=True, text=True, env=env,
                          timeout=300)


def test_command_on_a_running_scheduler(client, tmp_path):
    r = run_command("compress", SCANS[0], SCANS[1], "-o", str(tmp_path / "s.lex3dm"), "--max-error", "0.03",
                    "--scheduler", client.scheduler.address, "--json")
    assert r.returncode == 0, r.stderr
    summary = json.loads(r.stdout)
    assert summary["ok"] == 2 and summary["workers"] == 2
    assert (tmp_path / "s_001.lex3dm").read_bytes() == lex3d.compress(SCANS[1], max_error=0.03)
    r = run_command("compress", SCANS[1], "-o", str(tmp_path / "m.lex3dm"), "--max-error", "0.03",
                    "--objective", "mse", "--scheduler", client.scheduler.address, "--json")
    assert r.returncode == 0, r.stderr
    assert (tmp_path / "m.lex3dm").read_bytes() == lex3d.compress(SCANS[1], max_error=0.03, objective="mse")


def test_command_exit_codes_and_messages(tmp_path):
    r = run_command("compress", SCANS[0], str(tmp_path / "missing.bin"), "-o", str(tmp_path / "c.lex3dm"),
                    "--max-error", "0.03", "--workers", "2", "--no-progress")
    assert r.returncode == 2, r.stderr
    assert "1 of 2 scans" in r.stdout and "missing.bin" in r.stderr
    assert (tmp_path / "c_000.lex3dm").exists() and not (tmp_path / "c_001.lex3dm").exists()
    r = run_command("compress", SCANS[0], "-o", str(tmp_path / "d.lex3dm"), "--scheduler", "tcp://127.0.0.1:9",
                    "--timeout", "2")
    assert r.returncode == 3
    assert r.stderr.strip().startswith("lex3d-dask: cannot reach the Dask scheduler at tcp://127.0.0.1:9")
    assert len(r.stderr.strip().splitlines()) == 1
    r = run_command("compress", SCANS[0], "-o", SCANS[0], "--max-error", "0.03", "--workers", "1")
    assert r.returncode == 1 and "would overwrite the input" in r.stderr
    r = run_command("compress", SCANS[0])
    assert r.returncode == 1 and "-o/--output" in r.stderr


def test_bad_options_and_alphabet_are_refused_before_any_work(client, tmp_path):
    with pytest.raises(lex3d.dask.CompressError, match="max_error must be metres") as e:
        lex3d.dask.compress(SCANS, tmp_path / "o.lex3dm", client=client, max_error=50.0)
    assert e.value.code == 1
    (tmp_path / "bad.lex3da").write_bytes(b"not an alphabet")
    with pytest.raises(lex3d.dask.CompressError, match="bad.lex3da: alphabet: .*bad magic") as e:
        lex3d.dask.compress(SCANS, tmp_path / "o.lex3dm", client=client, alphabet=tmp_path / "bad.lex3da")
    assert e.value.code == 2
    assert sorted(p.name for p in tmp_path.iterdir()) == ["bad.lex3da"]


def test_an_interrupted_job_says_what_was_not_written_and_closes_its_client(client, tmp_path, monkeypatch, capsys):
    from lex3d.dask import _learn, cli
    opened = []
    real_client = cli._client

    def tracked_client(args):
        c, cluster = real_client(args)
        opened.append(c)
        return c, cluster

    def interrupted(*args, **kwargs):
        raise KeyboardInterrupt

    monkeypatch.setattr(cli, "_client", tracked_client)
    monkeypatch.setattr(cli, "compress", interrupted)
    monkeypatch.setattr(_learn, "learn", interrupted)
    for command, message in (("compress", "(no partial output files; the manifest is not written)"),
                             ("learn", "(no alphabet written)")):
        code = cli.main([command, SCANS[0], "-o", str(tmp_path / "out"), "--scheduler", client.scheduler.address])
        assert code == 130
        assert capsys.readouterr().err == f"lex3d-dask: interrupted {message}\n"
        assert len(opened) == 1 and opened.pop().status == "closed"
    assert list(tmp_path.iterdir()) == []


def test_the_progress_line_is_throttled_and_the_last_one_ends_it(capsys):
    from lex3d.dask._progress import ProgressLine
    line = ProgressLine("coding", 4, True, lambda done, elapsed_s, failed: f", {failed} failed")
    line.update(1, 0)
    line.update(2, 0)  # within 0.2 s of the one before: not drawn
    line.update(4, 1, final=True)
    assert capsys.readouterr().err == ("\rcoding [" + "#" * 7 + "." * 23 + "] 1/4, 0 failed"
                                       "\rcoding [" + "#" * 30 + "] 4/4, 1 failed\n")
    calls = []
    line = ProgressLine("learning", 9, lambda *a: calls.append(a), lambda *a: "")
    line.update(3, "x")
    line.update(9, "y", final=True)
    assert calls == [(3, 9, "x")] and capsys.readouterr().err == ""
