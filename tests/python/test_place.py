"""lex3d.PlaceDatabase: built from the sample scans (the same bytes as `lex3d place build`),
queried with a moved copy of one of them (the right scan and the inverse of the motion come
back), saved and opened again with the same answers, scans given as arrays, paths and model
bytes, and bad input as ValueError / OSError with one line. Run by ctest (python.tests)."""

import os
import pathlib
import subprocess
import threading
import time

import numpy as np
import pytest

import lex3d

SAMPLES = pathlib.Path(os.environ.get("LEX3D_SAMPLES", pathlib.Path(__file__).parents[2] / "samples"))
CLI = os.environ.get("LEX3D_CLI")
SCANS = [SAMPLES / "newer_college_00.bin", SAMPLES / "kitti00_000000.bin", SAMPLES / "room_scan1.pcd"]


def points_of(path):
    raw = np.fromfile(path, dtype="<f4").reshape(-1, 4 if "kitti" in path.name else 3)
    keep = np.isfinite(raw[:, :3]).all(axis=1) & (raw[:, :3] != 0).any(axis=1)
    return raw[keep, :3]


def yaw_motion(deg, t):
    c, s = np.cos(np.radians(deg)), np.sin(np.radians(deg))
    T = np.eye(4)
    T[:2, :2] = [[c, -s], [s, c]]
    T[:3, 3] = t
    return T


@pytest.fixture(scope="module")
def db():
    return lex3d.PlaceDatabase.build(SCANS, learn_scans=2, iterations=60)


def moved(points, T):
    return (points.astype(np.float64) @ T[:3, :3].T + T[:3, 3]).astype(np.float32)


def check_found(matches, name, T_query_match):
    """The best match is `name`, accepted, at the pose that undoes the motion."""
    assert matches, "no candidate"
    best = matches[0]
    assert best["scan"] == name and best["valid"] and best["accepted"], matches[0]
    assert [m["score"] for m in matches] == sorted((m["score"] for m in matches), reverse=True)
    pose = best["pose"]
    assert pose.shape == (4, 4) and pose.dtype == np.float64
    err = pose @ T_query_match  # identity when T_match_query is the inverse of the motion
    assert np.linalg.norm(err[:3, 3]) < 0.15
    angle = np.degrees(np.arccos(np.clip((np.trace(err[:3, :3]) - 1) / 2, -1, 1)))
    assert angle < 2.0


def test_build_names_and_length(db):
    assert len(db) == 3
    assert db.names == ["newer_college_00", "kitti00_000000", "room_scan1"]
    assert db.alphabet_words > 0
    assert "3 scans" in repr(db)


def test_a_moved_copy_finds_its_scan_and_the_motion(db):
    T = yaw_motion(25.0, [1.0, -0.5, 0.0])
    check_found(db.query(moved(points_of(SCANS[0]), T)), "newer_college_00", T)


def test_saved_and_opened_gives_the_same_answers(db, tmp_path):
    path = tmp_path / "places.lex3dp"
    db.save(path)
    opened = lex3d.PlaceDatabase.open(path)
    assert len(opened) == 3 and opened.names == db.names and opened.path == str(path)
    query = moved(points_of(SCANS[1]), yaw_motion(-10.0, [0.5, 0.2, 0.0]))
    a, b = db.query(query), opened.query(query)
    assert [(m["scan"], m["score"]) for m in a] == [(m["scan"], m["score"]) for m in b]
    for x, y in zip(a, b):
        assert np.array_equal(x["pose"], y["pose"])
    assert a[0]["scan"] == "kitti00_000000"


def test_add_then_query_and_model_bytes_as_scans(db, tmp_path):
    path = tmp_path / "grow.lex3dp"
    db.save(path)
    grown = lex3d.PlaceDatabase.open(path)
    # A scan added as a model file (bytes): the decoded points within 2 cm of the scan's.
    data = lex3d.compress(points_of(SCANS[0]), max_error=0.02)
    T = yaw_motion(90.0, [0.0, 3.0, 0.0])
    index = grown.add(moved(points_of(SCANS[0]), T), name="turned")
    assert index == 3 and len(grown) == 4 and grown.names[-1] == "turned"
    matches = grown.query(data, top=4)
    names = [m["scan"] for m in matches[:2]]
    assert set(names) == {"newer_college_00", "turned"}
    turned = next(m for m in matches if m["scan"] == "turned")
    # the turned copy: query (original frame) -> its frame is the motion itself
    assert turned["valid"]
    assert np.linalg.norm(turned["pose"][:3, 3] - T[:3, 3]) < 0.15
    grown.save(path)
    assert len(lex3d.PlaceDatabase.open(path)) == 4


def test_pose_or_gravity_make_a_tilted_scan_upright(db):
    # The scan tilted by 20 degrees about x: with the true gravity it is found again.
    c, s = np.cos(np.radians(20)), np.sin(np.radians(20))
    T = np.eye(4)
    T[1:3, 1:3] = [[c, -s], [s, c]]
    query = moved(points_of(SCANS[0]), T)
    gravity = T[:3, :3] @ np.array([0.0, 0.0, -1.0])  # the world's down in the tilted frame
    check_found(db.query(query, gravity=gravity), "newer_college_00", T)
    check_found(db.query(query, pose=np.linalg.inv(T)), "newer_college_00", T)


def test_bad_input_raises_one_line(db, tmp_path):
    with pytest.raises(OSError, match="nothing-here.lex3dp"):
        lex3d.PlaceDatabase.open(tmp_path / "nothing-here.lex3dp")
    garbage = tmp_path / "garbage.lex3dp"
    garbage.write_bytes(b"not a database at all" * 10)
    with pytest.raises(ValueError, match="garbage.lex3dp"):
        lex3d.PlaceDatabase.open(garbage)
    q = points_of(SCANS[0])
    with pytest.raises(ValueError, match="pose must be a 4x4"):
        db.query(q, pose=np.eye(3))
    with pytest.raises(ValueError, match="not a rigid transform"):
        db.query(q, pose=np.diag([2.0, 1.0, 1.0, 1.0]))
    with pytest.raises(ValueError, match="pose or gravity, not both"):
        db.query(q, pose=np.eye(4), gravity=np.array([0, 0, -1.0]))
    with pytest.raises(ValueError, match="gravity must be a finite, non-zero"):
        db.query(q, gravity=np.zeros(3))
    with pytest.raises(ValueError, match=r"scan must have shape \(N, 3\)"):
        db.query(np.zeros((5, 2), np.float32))
    with pytest.raises(ValueError, match="top must be at least 1"):
        db.query(q, top=0)
    with pytest.raises(ValueError, match="names has 1 entries for 3 scans"):
        lex3d.PlaceDatabase.build(SCANS, names=["a"])
    with pytest.raises(ValueError, match="alphabet"):
        lex3d.PlaceDatabase.build(SCANS, alphabet=b"nope")
    with pytest.raises(ValueError):
        db.add(b"\x00" * 40)  # not a model file
    assert len(db) == 3



@pytest.mark.skipif(not CLI, reason="LEX3D_CLI not set (run through ctest)")
def test_built_and_saved_as_the_command_builds_it(tmp_path):
    alphabet = lex3d.learn_alphabet(SCANS[:2], iterations=40)
    (tmp_path / "a.lex3da").write_bytes(alphabet)
    subprocess.run([CLI, "place", "build", str(tmp_path / "cli.lex3dp"), *map(str, SCANS),
                    "--alphabet", str(tmp_path / "a.lex3da")], check=True, capture_output=True)
    lex3d.PlaceDatabase.build(SCANS, alphabet=alphabet).save(tmp_path / "py.lex3dp")
    assert (tmp_path / "py.lex3dp").read_bytes() == (tmp_path / "cli.lex3dp").read_bytes()


@pytest.mark.skipif(not CLI, reason="LEX3D_CLI not set (run through ctest)")
def test_learned_and_saved_as_the_command_learns_it(tmp_path):
    subprocess.run([CLI, "place", "build", str(tmp_path / "cli.lex3dp"), *map(str, SCANS), "--learn-scans", "2",
                    "--iterations", "60", "--threads", "1"], check=True, capture_output=True)
    lex3d.PlaceDatabase.build(SCANS, learn_scans=2, iterations=60).save(tmp_path / "py.lex3dp")
    assert (tmp_path / "py.lex3dp").read_bytes() == (tmp_path / "cli.lex3dp").read_bytes()


def test_a_bad_scan_to_learn_on_raises_one_line(tmp_path):
    (tmp_path / "short.bin").write_bytes(b"\x00" * 5)
    with pytest.raises(ValueError, match="short.bin"):
        lex3d.PlaceDatabase.build([SCANS[0], tmp_path / "short.bin"], learn_scans=2, iterations=5)


def test_a_query_lets_other_python_threads_run(db):
    """The GIL is released while the query works: a ticking thread keeps ticking."""
    ticks, stop = [], threading.Event()

    def tick():
        while not stop.is_set():
            ticks.append(time.perf_counter())
            time.sleep(0.001)

    query = moved(points_of(SCANS[1]), yaw_motion(5.0, [0.3, 0.0, 0.0]))
    ticker = threading.Thread(target=tick)
    ticker.start()
    time.sleep(0.05)
    # queries until 0.2 s have passed (one takes 30-90 ms)
    t0 = time.perf_counter()
    queries = 0
    while queries == 0 or time.perf_counter() - t0 < 0.2:
        db.query(query, threads=1)
        queries += 1
    t1 = time.perf_counter()
    stop.set()
    ticker.join()
    inside = [t0] + [t for t in ticks if t0 <= t <= t1] + [t1]
    longest = max(b - a for a, b in zip(inside, inside[1:]))
    # a lock held through a query would stop the ticks for about a query's time
    assert longest < 0.5 * (t1 - t0) / queries, (longest, t1 - t0, queries)


def test_results_do_not_depend_on_threads(db, tmp_path):
    assert db.threads == 2
    one = lex3d.PlaceDatabase.build(SCANS, learn_scans=2, iterations=60, threads=1)
    assert one.threads == 1
    assert one.alphabet_file() == db.alphabet_file()
    db.save(tmp_path / "two.lex3dp")
    one.save(tmp_path / "one.lex3dp")
    assert (tmp_path / "one.lex3dp").read_bytes() == (tmp_path / "two.lex3dp").read_bytes()
    every = lex3d.PlaceDatabase.open(tmp_path / "one.lex3dp", threads=0)
    assert every.threads == min(64, max(1, os.cpu_count() or 1))
    query = moved(points_of(SCANS[0]), yaw_motion(25.0, [1.0, -0.5, 0.0]))
    assert one.prepare_query(query) == db.prepare_query(query)
    answers = [one.query(query), db.query(query), every.query(query), db.query(query, threads=1)]
    for a in answers[1:]:
        assert [(m["scan"], m["score"], m["inliers"]) for m in a] == \
            [(m["scan"], m["score"], m["inliers"]) for m in answers[0]]
        for x, y in zip(a, answers[0]):
            assert np.array_equal(x["pose"], y["pose"])
    assert answers[0][0]["scan"] == "newer_college_00"
    for bad in (-1, 65):
        with pytest.raises(ValueError, match="threads must be 0 .every core. to 64, got"):
            lex3d.PlaceDatabase.open(tmp_path / "one.lex3dp", threads=bad)
        with pytest.raises(ValueError, match="threads must be"):
            db.query(query, threads=bad)
