"""lex3d.dask.compress on files that hold several scans (a raw capture's turns, a ROS bag's
messages): each scan is one output, the files byte for byte those of `lex3d compress` on the
same inputs; a capture damaged part way gives its turns before the damage and one error row;
an alphabet learned on a capture's turns. Run by ctest (python.tests)."""

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

ROOT = pathlib.Path(__file__).parents[2]
SAMPLES = pathlib.Path(os.environ.get("LEX3D_SAMPLES", ROOT / "samples"))
CLI = os.environ.get("LEX3D_CLI")
CAPTURE = SAMPLES / "vlp16_velodyne_example.pcap"
ROOM = SAMPLES / "room_scan1.pcd"

pytestmark = pytest.mark.skipif(not CLI, reason="LEX3D_CLI not set (run through ctest)")


@pytest.fixture(scope="module")
def capture(tmp_path_factory):
    """The sample capture's first turn repeated: a capture of several whole turns."""
    out = tmp_path_factory.mktemp("capture") / "turns.pcap"
    subprocess.run([sys.executable, str(ROOT / "bench" / "long_capture.py"), str(CAPTURE), str(out), "4"],
                   check=True, capture_output=True)
    return out


def manifest_rows(path):
    lines = pathlib.Path(path).read_text().splitlines()
    return json.loads(lines[0]), [json.loads(line) for line in lines[1:]]


def command_files(tmp_path, inputs, args):
    ref = tmp_path / "cli" / "s.lex3dm"
    ref.parent.mkdir()
    subprocess.run([CLI, "compress", *map(str, inputs), "-o", str(ref), *args], check=True, capture_output=True)
    return sorted(ref.parent.iterdir())


def test_a_capture_counts_as_its_turns(client, tmp_path, capture):
    turns = len(list(lex3d.scans(capture)))
    assert turns >= 3
    inputs = [capture, ROOM]
    out = tmp_path / "dask" / "s.lex3dm"
    out.parent.mkdir()
    summary = lex3d.dask.compress(inputs, out, client=client, max_error=0.02, batch=2)
    assert summary["scans"] == turns + 1 and summary["ok"] == turns + 1 and summary["failed"] == 0
    expected = command_files(tmp_path, inputs, ["--max-error", "0.02"])
    assert [p.name for p in expected] == [f"s_{i:03d}.lex3dm" for i in range(turns + 1)]
    for ref in expected:
        assert (out.parent / ref.name).read_bytes() == ref.read_bytes(), ref.name
    header, rows = manifest_rows(summary["manifest"])
    assert header["scans"] == turns + 1
    assert [r["index"] for r in rows] == list(range(turns + 1))
    assert [r["scan"].split(" (")[0] for r in rows[:turns]] == [f"{capture} turn {k}" for k in range(turns)]
    assert rows[-1]["scan"] == str(ROOM)
    assert all(r["status"] == "ok" for r in rows)
    # the turns travelled pickled: more bytes to the workers than the paths alone would take
    assert summary["bytes_to_workers"] > turns * 100000


def test_a_bag_counts_as_its_messages(client, tmp_path, capture):
    bag = tmp_path / "turns.bag"
    r = subprocess.run([CLI, "convert", str(capture), str(bag)], capture_output=True, text=True)
    if r.returncode != 0 and "without ROS bag support" in r.stderr:
        pytest.skip("lex3d built without ROS bag support")
    assert r.returncode == 0, r.stderr
    out = tmp_path / "dask" / "b.lex3dm"
    out.parent.mkdir()
    summary = lex3d.dask.compress([bag], out, client=client, max_error=0.02)
    expected = command_files(tmp_path, [bag], ["--max-error", "0.02"])
    assert summary["ok"] == len(expected) >= 3
    for ref in expected:
        assert (out.parent / ref.name.replace("s_", "b_")).read_bytes() == ref.read_bytes(), ref.name


def test_a_capture_damaged_part_way_gives_its_turns_then_one_error(client, tmp_path):
    # (past the 4,096 packets a Velodyne capture's model is read from: the turns before the
    # damage come out before its error)
    long = tmp_path / "long.pcap"
    subprocess.run([sys.executable, str(ROOT / "bench" / "long_capture.py"), str(CAPTURE), str(long), "64"],
                   check=True, capture_output=True)
    data = long.read_bytes()
    damaged = tmp_path / "damaged.pcap"
    damaged.write_bytes(data[: int(len(data) * 0.95)])  # the last record cut short
    full = len(list(lex3d.scans(long)))
    out = tmp_path / "d.lex3dm"
    summary = lex3d.dask.compress([damaged, ROOM], out, client=client, max_error=0.1)
    _, rows = manifest_rows(summary["manifest"])
    statuses = [r["status"] for r in rows]
    assert summary["failed"] == 1 and statuses.count("error") == 1
    bad = statuses.index("error")
    assert 1 <= bad < full and statuses[:bad] == ["ok"] * bad and statuses[bad + 1:] == ["ok"]
    assert str(damaged) in rows[bad]["error"] and "\n" not in rows[bad]["error"]
    assert not pathlib.Path(rows[bad]["file"]).exists()
    # the command line says so and exits 2
    damaged.write_bytes(data[: int(len(data) * 0.02)])  # now in its first turns
    r = subprocess.run([sys.executable, "-m", "lex3d.dask", "compress", str(damaged), "-o", str(tmp_path / "e.lex3dm"),
                        "--max-error", "0.1", "--workers", "1", "--no-progress"], capture_output=True, text=True)
    assert r.returncode == 2, r.stderr
    assert str(damaged) in r.stderr


def test_an_alphabet_learned_on_a_captures_turns(client, tmp_path, capture):
    out = tmp_path / "dask" / "w.lex3dm"
    out.parent.mkdir()
    summary = lex3d.dask.compress([capture], out, client=client, learn_scans=2, iterations=40)
    assert summary["alphabet"] and summary["failed"] == 0
    expected = command_files(tmp_path, [capture], ["--alphabet", summary["alphabet"], "--max-error", "none"])
    assert len(expected) == summary["scans"]
    for ref in expected:
        assert (out.parent / ref.name.replace("s_", "w_")).read_bytes() == ref.read_bytes(), ref.name


def test_learn_on_a_capture_learns_the_commands_alphabet(client, tmp_path, capture):
    ref = tmp_path / "cli.lex3da"
    subprocess.run([CLI, "learn", str(capture), "-o", str(ref), "--iterations", "40"], check=True, capture_output=True)
    summary = lex3d.dask.learn([capture], tmp_path / "dask.lex3da", client=client, iterations=40)
    assert summary["scans"] == len(list(lex3d.scans(capture)))
    assert (tmp_path / "dask.lex3da").read_bytes() == ref.read_bytes()


def test_place_shards_of_a_capture_answer_as_the_commands_database(client, tmp_path, capture):
    alphabet = tmp_path / "a.lex3da"
    subprocess.run([CLI, "learn", str(capture), "-o", str(alphabet), "--iterations", "40"], check=True,
                   capture_output=True)
    whole = tmp_path / "whole.lex3dp"
    subprocess.run([CLI, "place", "build", str(whole), str(capture), "--alphabet", str(alphabet)], check=True,
                   capture_output=True)
    one = lex3d.PlaceDatabase.open(whole)
    s = lex3d.dask.build_place_shards([capture], tmp_path / "db", client=client, shards=2, alphabet=alphabet)
    assert s["scans"] == len(one.names) >= 3
    manifest = json.loads((tmp_path / "db" / "manifest.json").read_text())
    assert [n for x in manifest["shards"] for n in x["names"]] == list(one.names)
    db = lex3d.dask.ShardedPlaceDatabase(tmp_path / "db", client)
    for turn in lex3d.scans(capture):
        a, b = one.query(turn, top=3), db.query(turn, top=3)
        assert [m["scan"] for m in a] == [m["scan"] for m in b]
        assert [m["score"] for m in a] == pytest.approx([m["score"] for m in b])
    # the command lines: a capture given as queries is one query a turn on both
    cli = subprocess.run([CLI, "place", "query", str(whole), str(capture), "--json"], check=True,
                         capture_output=True, text=True).stdout.splitlines()
    r = subprocess.run([sys.executable, "-m", "lex3d.dask", "place", "query", str(tmp_path / "db"), str(capture),
                        "--scheduler", client.scheduler.address, "--json"], capture_output=True, text=True)
    assert r.returncode == 0, r.stderr
    dask_answers = json.loads(r.stdout)
    cli_answers = [json.loads(line) for line in cli]
    assert len(dask_answers) == len(cli_answers) == len(one.names)
    for a, b in zip(cli_answers, dask_answers):
        assert [m["scan"] for m in a["matches"][:3]] == [m["scan"] for m in b["matches"][:3]]


def test_a_worker_killed_mid_job_loses_no_carried_scan(tmp_path):
    # The turns travel inside their tasks: a task retried after its worker died still has them.
    long = tmp_path / "long.pcap"
    subprocess.run([sys.executable, str(ROOT / "bench" / "long_capture.py"), str(CAPTURE), str(long), "24"],
                   check=True, capture_output=True)
    turns = list(lex3d.scans(long))
    result, done_when_killed = compress_killing_a_worker(tmp_path, lambda c: lex3d.dask.compress(
        [long], tmp_path / "k.lex3dm", client=c, max_error=0.02, window=4, batch=1))
    assert done_when_killed < len(turns)  # the kill came mid-job
    assert result["ok"] == len(turns) and result["failed"] == 0
    for k, turn in enumerate(turns):
        assert (tmp_path / f"k_{k:03d}.lex3dm").read_bytes() == lex3d.compress(turn, max_error=0.02), k


def test_a_sequence_file_counts_as_its_scans(client, tmp_path, capture):
    seq = tmp_path / "drive.lex3dq"
    subprocess.run([CLI, "compress", str(capture), str(ROOM), "-o", str(seq), "--one-file", "--max-error", "0.02"],
                   check=True, capture_output=True)
    names = lex3d.scans(seq).names  # listed up front: counted without decoding
    assert len(names) == len(list(lex3d.scans(capture))) + 1
    out = tmp_path / "dask" / "q.lex3dm"
    out.parent.mkdir()
    summary = lex3d.dask.compress([seq], out, client=client, max_error=0.05)
    expected = command_files(tmp_path, [seq], ["--max-error", "0.05"])
    assert summary["ok"] == len(expected) == len(names)
    for ref in expected:
        assert (out.parent / ref.name.replace("s_", "q_")).read_bytes() == ref.read_bytes(), ref.name
    _, rows = manifest_rows(summary["manifest"])
    assert [r["scan"] for r in rows] == names
