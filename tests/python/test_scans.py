"""lex3d.scans: the scans of a file one at a time (a capture's turns, a bag topic's scans, a
sequence file's scans, any other file's one scan), each a lex3d.Scan that lex3d.compress takes
with everything its file gave: the same bytes as `lex3d compress` on the same file. Run by
ctest (python.tests), which sets LEX3D_CLI and LEX3D_SAMPLES."""

import os
import pathlib
import subprocess

import numpy as np
import pytest

import lex3d

SAMPLES = pathlib.Path(os.environ.get("LEX3D_SAMPLES", pathlib.Path(__file__).parents[2] / "samples"))
CLI = os.environ.get("LEX3D_CLI")
CAPTURE = SAMPLES / "vlp16_velodyne_example.pcap"


def test_a_capture_gives_its_turns_with_their_fields_and_stamps():
    turns = list(lex3d.scans(CAPTURE))
    assert len(turns) == 1  # 1.1 turns: one complete
    t = turns[0]
    assert isinstance(t, lex3d.Scan)
    assert t.name.startswith(str(CAPTURE) + " turn 0")
    assert t.points.shape == (len(t), 3) and t.points.dtype == np.float32
    assert len(t) > 20000
    assert sorted(t.fields) == ["intensity", "ring", "time"]
    assert t.fields["ring"].max() == 15
    assert t.fields["time"].dtype == np.float32  # as Velodyne's driver gives it
    assert t.stamp["source"] == "capture" and t.stamp["sec"] > 1500000000
    # the first turn of a path, read by compress itself, is the same scan
    assert lex3d.compress(t, max_error=0.02) == lex3d.compress(str(CAPTURE), max_error=0.02)


@pytest.mark.skipif(not CLI, reason="LEX3D_CLI not set (run through ctest)")
def test_compress_of_each_scan_is_the_commands_file(tmp_path):
    # a capture's turn
    out = tmp_path / "turn.lex3dm"
    subprocess.run([CLI, "compress", str(CAPTURE), "-o", str(out), "--max-error", "0.02"], check=True, capture_output=True)
    (turn,) = lex3d.scans(CAPTURE)
    assert lex3d.compress(turn, max_error=0.02) == out.read_bytes()
    # a sequence file's scans: its turns again, decoded, in order
    seq = tmp_path / "turns.lex3dq"
    subprocess.run([CLI, "compress", str(CAPTURE), str(SAMPLES / "room_scan1.pcd"), "-o", str(seq), "--one-file",
                    "--max-error", "0.02"], check=True, capture_output=True)
    decoded = list(lex3d.scans(seq))
    assert len(decoded) == 2
    assert abs(len(decoded[0]) - len(turn)) < 0.01 * len(turn)
    assert decoded[0].stamp == turn.stamp
    assert "ring" in decoded[0].fields


@pytest.mark.skipif(not CLI, reason="LEX3D_CLI not set (run through ctest)")
def test_a_bag_gives_its_scans_one_at_a_time(tmp_path):
    bag = tmp_path / "scans.bag"
    r = subprocess.run([CLI, "convert", str(CAPTURE), str(bag)], capture_output=True, text=True)
    if r.returncode != 0 and "without ROS bag support" in r.stderr:
        pytest.skip("lex3d built without ROS bag support")
    assert r.returncode == 0, r.stderr
    (scan,) = lex3d.scans(bag)
    (turn,) = lex3d.scans(CAPTURE)
    assert scan.stamp["source"] == "message" and scan.stamp["sec"] == turn.stamp["sec"]
    assert len(scan) == len(turn)
    assert np.array_equal(np.sort(scan.points, axis=0), np.sort(turn.points, axis=0))


def test_a_file_of_one_scan_and_bad_input():
    (room,) = lex3d.scans(SAMPLES / "room_scan1.pcd")
    assert len(room) > 100000 and room.stamp is None
    with pytest.raises(OSError):
        lex3d.scans(SAMPLES / "no_such_file.pcap")
    with pytest.raises(ValueError, match="path"):
        lex3d.scans(np.zeros((3, 3), np.float32))
    with pytest.raises(ValueError, match="lex3d.Scan"):
        lex3d.compress(room, max_error=0.02, intensity=np.zeros(len(room), np.float32))
    with pytest.raises(ValueError, match="lex3d.scans"):
        lex3d.compress(room, max_error=0.02, single_return=True)


def test_a_scan_pickles_whole():
    import pickle
    (turn,) = lex3d.scans(CAPTURE)
    back = pickle.loads(pickle.dumps(turn))
    assert back.name == turn.name and len(back) == len(turn) and back.stamp == turn.stamp
    assert np.array_equal(back.points, turn.points)
    assert sorted(back.fields) == sorted(turn.fields)
    for k, v in turn.fields.items():
        assert back.fields[k].dtype == v.dtype and np.array_equal(back.fields[k], v)
    # the laser table read from the capture came too: the same file
    assert lex3d.compress(back, max_error=0.02) == lex3d.compress(turn, max_error=0.02)
    # a damaged pickle is an error, not a crash
    name, blob = turn.__getstate__()
    fresh = lex3d.Scan.__new__(lex3d.Scan)
    with pytest.raises(ValueError, match="not a lex3d cloud: a count beyond the bytes"):
        fresh.__setstate__((name, blob[: len(blob) // 2]))


def test_holds_scans_tells_the_files_of_several_scans(tmp_path):
    assert lex3d.holds_scans(CAPTURE) == "capture"
    assert lex3d.holds_scans(SAMPLES / "room_scan1.pcd") == ""
    assert lex3d.holds_scans(tmp_path / "x.lex3dq") == "sequence"
    assert lex3d.scans(CAPTURE).names is None  # a capture's scans are known only by reading it
