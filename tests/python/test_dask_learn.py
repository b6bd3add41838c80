"""lex3d.dask learn on a real LocalCluster (a scheduler and 2 worker processes on loopback):
the alphabet is byte for byte that of `lex3d learn` (and lex3d.learn_alphabet) on the same
scans with the same seed, also when a worker is killed mid-loop; a scan that cannot be read is
named and nothing is written; the command's exit codes. Run by ctest (python.tests)."""

import json
import os
import pathlib
import signal
import subprocess
import sys

import pytest

import lex3d

distributed = pytest.importorskip("distributed")
import lex3d.dask  # noqa: E402
from lex3d._lex3d import learning  # noqa: E402

SAMPLES = pathlib.Path(os.environ.get("LEX3D_SAMPLES", pathlib.Path(__file__).parents[2] / "samples"))
SHARED = pathlib.Path(os.environ.get("LEX3D_SHARED_DATA") or pathlib.Path(__file__).parents[3] / "shared" / "data")
CLI = os.environ.get("LEX3D_CLI")
SCANS = [str(SAMPLES / "kitti00_000000.bin"), str(SAMPLES / "newer_college_00.bin"), str(SAMPLES / "room_scan1.pcd")]


def balm(count):
    folder = SHARED / "balm"
    if not folder.is_dir():
        pytest.skip(f"{folder} is absent")
    return [str(p) for p in sorted(folder.glob("*.bin"))[:count]]


def test_the_pieces_in_one_process_give_learn_alphabet():
    # LearnScan and LearnDecisions driven from Python, scans evaluated in reverse order but
    # summed in scan order: the alphabet of lex3d.learn_alphabet.
    scans = [learning.LearnScan(s) for s in SCANS]
    radius = scans[0].set_word_radius()
    for s in scans:
        s.prepare(radius)
    loop = learning.LearnDecisions([s.features for s in scans], [s.points for s in scans],
                                   [s.log_likelihood for s in scans], iterations=40, seed=3)
    spacing = learning.point_spacing(radius)
    words = []
    while (c := loop.next()) is not None:
        word = scans[c[0]].cut_word(c[1], spacing)
        deltas = [0.0] * len(scans)
        if learning.LearnDecisions.evaluates(word):
            for i in reversed(range(len(scans))):
                deltas[i] = scans[i].evaluate(word, len(words))
        delta = 0.0
        for d in deltas:
            delta += d
        if loop.accepts(word, delta):
            log_l = 0.0
            for s in scans:
                log_l += s.commit(True)
            loop.accept(word, log_l)
            words.append(word)
        else:
            loop.reject()
    assert 0 < len(words) < 40 and loop.iteration == 40
    produced = learning.alphabet_file(radius, spacing, scans[0].descriptor_dim, words)
    assert produced == lex3d.learn_alphabet(SCANS, iterations=40, seed=3)
    # Another seed draws other candidates: another alphabet.
    assert produced != lex3d.learn_alphabet(SCANS, iterations=40, seed=4)


def test_a_bad_word_is_refused():
    s = learning.LearnScan(SCANS[1])
    s.prepare(0.5)
    with pytest.raises(ValueError, match="learning word"):
        s.evaluate(b"\x01\x00\x00\x00\x02\x00\x00\x00" + b"\x00" * 8, 0)
    with pytest.raises(ValueError, match="descriptor values"):
        s.evaluate(b"\x00\x00\x00\x00\x02\x00\x00\x00" + b"\x00" * 8, 0)


@pytest.mark.skipif(not CLI, reason="LEX3D_CLI not set (run through ctest)")
def test_same_alphabet_as_the_command(client, tmp_path):
    summary = lex3d.dask.learn(SCANS, tmp_path / "d.lex3da", client=client, iterations=60, seed=7)
    assert summary["workers"] == 2 and summary["shards"] == [[0, 1], [1, 3]]
    assert summary["iterations"] == 60 and summary["accepted"] == summary["words"] > 0
    subprocess.run([CLI, "learn", *SCANS, "-o", str(tmp_path / "c.lex3da"), "--iterations", "60", "--seed", "7"],
                   check=True, capture_output=True)
    produced = (tmp_path / "d.lex3da").read_bytes()
    assert produced == (tmp_path / "c.lex3da").read_bytes()
    assert summary["alphabet_bytes"] == len(produced)
    assert sorted(p.name for p in tmp_path.iterdir()) == ["c.lex3da", "d.lex3da"]


def test_same_alphabet_on_a_real_sequence(client, tmp_path):
    scans = balm(6)
    summary = lex3d.dask.learn(scans, tmp_path / "b.lex3da", client=client, iterations=50, patience=20, seed=2)
    assert summary["scans"] == 6 and summary["shards"] == [[0, 3], [3, 6]]
    assert (tmp_path / "b.lex3da").read_bytes() == lex3d.learn_alphabet(scans, iterations=50, patience=20, seed=2)


def test_a_worker_killed_mid_loop_changes_nothing(tmp_path):
    cluster = distributed.LocalCluster(n_workers=2, threads_per_worker=1, processes=True, host="127.0.0.1",
                                       dashboard_address=":0")
    c = distributed.Client(cluster)
    try:
        pids = sorted(c.run(os.getpid).values())
        killed = []

        def kill_at_ten(iteration, total, bic, words):
            if iteration == 10 and not killed:
                os.kill(pids[0], signal.SIGKILL)
                killed.append(words)

        summary = lex3d.dask.learn(SCANS, tmp_path / "k.lex3da", client=c, iterations=60, seed=7,
                                   progress=kill_at_ten)
        assert killed and killed[0] > 0  # killed with words accepted: the rebuilt shard replays them
        assert summary["rebuilt_shards"] >= 1 and summary["iterations"] == 60
        assert (tmp_path / "k.lex3da").read_bytes() == lex3d.learn_alphabet(SCANS, iterations=60, seed=7)
        assert [p.name for p in tmp_path.iterdir()] == ["k.lex3da"]
    finally:
        c.close()
        cluster.close()


def test_a_bad_scan_is_named_and_nothing_written(client, tmp_path):
    bad = tmp_path / "broken.pcd"
    bad.write_bytes(b"# .PCD v0.7\nVERSION 0.7\nFIELDS x y z\nSIZE 4 4 4\nTYPE F F F\nCOUNT 1 1 1\n"
                    b"WIDTH 1000\nHEIGHT 1\nPOINTS 1000\nDATA binary\n" + b"\x00" * 40)
    with pytest.raises(lex3d.dask.CompressError, match="broken.pcd") as e:
        lex3d.dask.learn([SCANS[0], str(bad), SCANS[1]], tmp_path / "a.lex3da", client=client, iterations=5)
    assert e.value.code == 2 and "\n" not in str(e.value)
    with pytest.raises(lex3d.dask.CompressError, match="iterations") as e:
        lex3d.dask.learn(SCANS, tmp_path / "a.lex3da", client=client, iterations=0)
    assert e.value.code == 1
    with pytest.raises(lex3d.dask.CompressError, match="would overwrite the input") as e:
        lex3d.dask.learn([SCANS[0], str(bad)], bad, client=client)
    assert e.value.code == 1
    assert [p.name for p in tmp_path.iterdir()] == ["broken.pcd"]


def run_command(*args):
    return subprocess.run([sys.executable, "-m", "lex3d.dask", *args], capture_output=True, text=True,
                          env=dict(os.environ), timeout=300)


def test_command_on_a_running_scheduler(client, tmp_path):
    r = run_command("learn", *SCANS[:2], "-o", str(tmp_path / "a.lex3da"), "--iterations", "30", "--seed", "5",
                    "--scheduler", client.scheduler.address, "--json")
    assert r.returncode == 0, r.stderr
    summary = json.loads(r.stdout)
    assert summary["workers"] == 2 and summary["scans"] == 2
    assert (tmp_path / "a.lex3da").read_bytes() == lex3d.learn_alphabet(SCANS[:2], iterations=30, seed=5)
    r = run_command("learn", SCANS[0], str(tmp_path / "missing.bin"), "-o", str(tmp_path / "m.lex3da"),
                    "--scheduler", client.scheduler.address)
    # As `lex3d learn`: a scan that cannot be read is bad input (2), one line naming it.
    assert r.returncode == 2 and not (tmp_path / "m.lex3da").exists()
    assert [line for line in r.stderr.splitlines() if line.startswith("lex3d-dask:")] == \
        [f"lex3d-dask: {tmp_path / 'missing.bin'}: cannot open: No such file or directory"]
    r = run_command("learn", SCANS[0], "-o", str(tmp_path / "u.lex3da"), "--scheduler", "tcp://127.0.0.1:9",
                    "--timeout", "2")
    assert r.returncode == 3 and "cannot reach the Dask scheduler" in r.stderr
    r = run_command("learn", SCANS[0])
    assert r.returncode == 1 and "-o/--output" in r.stderr


@pytest.mark.skipif(not os.environ.get("LEX3D_DASK"), reason="LEX3D_DASK not set (run through ctest)")
def test_the_lex3d_dask_command(client, tmp_path):
    exe = os.environ["LEX3D_DASK"]
    r = subprocess.run([exe, "--help"], capture_output=True, text=True, timeout=120)
    assert r.returncode == 0 and r.stdout.startswith("usage: lex3d-dask")
    assert "compress" in r.stdout and "learn" in r.stdout
    r = subprocess.run([exe, "learn", *SCANS[1:], "-o", str(tmp_path / "a.lex3da"), "--iterations", "20",
                        "--scheduler", client.scheduler.address], capture_output=True, text=True, timeout=300)
    assert r.returncode == 0, r.stderr
    assert r.stdout.startswith("learned ") and "from 2 scans" in r.stdout and "on 2 workers" in r.stdout
    assert (tmp_path / "a.lex3da").read_bytes() == lex3d.learn_alphabet(SCANS[1:], iterations=20)
