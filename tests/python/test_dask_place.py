"""lex3d.dask's sharded place database on a real LocalCluster (2 worker processes): shards of
consecutive scan ranges built on the workers with one alphabet answer every query exactly as
one database of all the scans (entry names, scores, transforms), through the Python API and
the command; a missing or corrupt shard is named in one line (exit 2). Run by ctest
(python.tests); the balm case skips without the shared data."""

import json
import os
import pathlib
import subprocess
import sys

import numpy as np
import pytest

import lex3d

distributed = pytest.importorskip("distributed")
import lex3d.dask  # noqa: E402
from lex3d.dask import _place  # noqa: E402

SAMPLES = pathlib.Path(os.environ.get("LEX3D_SAMPLES", pathlib.Path(__file__).parents[2] / "samples"))
SHARED = pathlib.Path(os.environ.get("LEX3D_SHARED_DATA") or pathlib.Path(__file__).parents[3] / "shared" / "data")
SCANS = [str(SAMPLES / "newer_college_00.bin"), str(SAMPLES / "kitti00_000000.bin"), str(SAMPLES / "room_scan1.pcd")]


def points_of(path):
    path = pathlib.Path(path)
    raw = np.fromfile(path, dtype="<f4").reshape(-1, 4 if "kitti" in path.name else 3)
    keep = np.isfinite(raw[:, :3]).all(axis=1) & (raw[:, :3] != 0).any(axis=1)
    return raw[keep, :3]


def moved(points, deg, t):
    c, s = np.cos(np.radians(deg)), np.sin(np.radians(deg))
    R = np.array([[c, -s, 0], [s, c, 0], [0, 0, 1]])
    return (points.astype(np.float64) @ R.T + np.asarray(t)).astype(np.float32)


@pytest.fixture(scope="module")
def alphabet(tmp_path_factory):
    """A place alphabet of the samples (learned once), as a file."""
    path = tmp_path_factory.mktemp("alphabet") / "samples.lex3da"
    path.write_bytes(lex3d.PlaceDatabase.build(SCANS, learn_scans=2, iterations=60).alphabet_file())
    return path


def expect_same(whole, sharded, what):
    assert [m["scan"] for m in sharded] == [m["scan"] for m in whole], what
    for a, b in zip(whole, sharded):
        for key in ("index", "score", "valid", "accepted", "inliers", "similarity", "sensor_distance_m"):
            assert a[key] == b[key], (what, a["scan"], key)  # bit for bit
        assert np.array_equal(a["pose"], b["pose"]), (what, a["scan"])


def test_sample_shards_answer_as_one_database(client, tmp_path, alphabet):
    s = lex3d.dask.build_place_shards(SCANS, tmp_path / "db", client=client, shards=2, alphabet=alphabet)
    assert s["scans"] == 3 and s["shards"] == 2
    manifest = json.loads((tmp_path / "db" / "manifest.json").read_text())
    assert [(x["first"], x["count"], x["entries"]) for x in manifest["shards"]] == [(0, 1, 1), (1, 2, 2)]
    assert [n for x in manifest["shards"] for n in x["names"]] == ["newer_college_00", "kitti00_000000", "room_scan1"]
    whole = lex3d.PlaceDatabase.build(SCANS, alphabet=alphabet.read_bytes())
    assert manifest["alphabet_sha256"] == _place._sha256(whole.alphabet_file())
    db = lex3d.dask.ShardedPlaceDatabase(tmp_path / "db", client)
    assert len(db) == 3 and db.stats[0] == 3
    assert np.array_equal(db.stats[1], whole.word_statistics()[1])
    for i, scan in enumerate(SCANS):
        q = moved(points_of(scan), 20.0, [0.7, -0.4, 0.0]) if scan.endswith(".bin") else scan
        for top_k in (2, 8):  # 2: fewer than the scans, the merge of the shards' top-K decides
            one = whole.query(q, top=10, top_k=top_k)
            timings = {}
            got = db.query(q, top=10, top_k=top_k, timings=timings)
            expect_same(one, got, f"{scan} top_k {top_k}")
            assert got[0]["scan"] == whole.names[i] and got[0]["accepted"]
            assert timings["bytes_from_workers"] > 0 and timings["query_bytes"] > 0


def test_balm_shards_answer_as_one_database(client, tmp_path):
    folder = SHARED / "balm"
    if not folder.is_dir():
        pytest.skip(f"{folder} is absent")
    frames = sorted(folder.glob("*.bin"))
    poses = _place.read_poses(str(folder / "poses.txt"), len(frames))
    pick = list(range(0, 60, 5))  # 12 scans of the first minute
    listing = tmp_path / "scans.txt"
    listing.write_text("".join(f"{frames[i]}\n" for i in pick))
    pose_file = tmp_path / "poses.txt"
    np.savetxt(pose_file, poses[pick, :3, :].reshape(len(pick), 12))
    s = lex3d.dask.build_place_shards([f"@{listing}"], tmp_path / "db", client=client, shards=3, poses=pose_file,
                                      learn_scans=2, iterations=60, seed=1)
    assert s["shards"] == 3
    alphabet = (tmp_path / "db" / "alphabet.lex3da").read_bytes()
    whole = lex3d.PlaceDatabase.build([str(frames[i]) for i in pick], poses=list(poses[pick]), alphabet=alphabet)
    db = lex3d.dask.ShardedPlaceDatabase(tmp_path / "db", client)
    for i in (62, 88, 55, 4):  # 000124, 000176, 000110, 000008
        expect_same(whole.query(str(frames[i]), pose=poses[i], top=8),
                    db.query(str(frames[i]), pose=poses[i], top=8), frames[i].name)


def run_command(*args):
    return subprocess.run([sys.executable, "-m", "lex3d.dask", *args], capture_output=True, text=True,
                          env=dict(os.environ), timeout=300)


def test_command_and_bad_shards(client, tmp_path, alphabet):
    address = client.scheduler.address
    r = run_command("place", "build", *SCANS, "-o", str(tmp_path / "db"), "--scans-per-shard", "2",
                    "--alphabet", str(alphabet), "--scheduler", address, "--json")
    assert r.returncode == 0, r.stderr
    assert json.loads(r.stdout)["shards"] == 2
    r = run_command("place", "query", str(tmp_path / "db"), SCANS[1], "--scheduler", address, "--json")
    assert r.returncode == 0, r.stderr
    answer = json.loads(r.stdout)[0]
    whole = lex3d.PlaceDatabase.build(SCANS, alphabet=alphabet.read_bytes()).query(SCANS[1], top=3)
    assert [m["scan"] for m in answer["matches"]] == [m["scan"] for m in whole]
    assert [m["score"] for m in answer["matches"]] == [m["score"] for m in whole]
    assert np.array_equal(np.array(answer["matches"][0]["pose"]), whole[0]["pose"])
    # Usage errors (exit 1) before any work.
    r = run_command("place", "build", *SCANS, "-o", str(tmp_path / "u"), "--shards", "2", "--scans-per-shard", "2")
    assert r.returncode == 1 and "--shards or --scans-per-shard" in r.stderr and not (tmp_path / "u").exists()
    r = run_command("place", "build", *SCANS, "-o", str(tmp_path / "db"), "--shards", "2", "--scheduler", address)
    assert r.returncode == 1 and "already holds" in r.stderr
    # A scan that cannot be read: named, exit 2, and no partial database (no folder, no shard).
    r = run_command("place", "build", SCANS[0], str(tmp_path / "missing.bin"), "-o", str(tmp_path / "p"),
                    "--shards", "2", "--alphabet", str(alphabet), "--scheduler", address)
    assert r.returncode == 2 and "missing.bin" in r.stderr and len(r.stderr.strip().splitlines()) == 1, r.stderr
    assert not (tmp_path / "p").exists()
    # A corrupt entry is found when a query verifies it: named in one line, exit 2.
    shard = tmp_path / "db" / "shard_000.lex3dp"
    data = bytearray(shard.read_bytes())
    intact = bytes(data)
    data[len(data) // 3] ^= 0x55
    shard.write_bytes(bytes(data))
    r = run_command("place", "query", str(tmp_path / "db"), SCANS[0], "--scheduler", address)
    assert r.returncode == 2, r.stdout + r.stderr
    assert "shard_000.lex3dp" in r.stderr and len(r.stderr.strip().splitlines()) == 1, r.stderr
    # A shard whose header is damaged is refused when the database is opened.
    shard.write_bytes(b"XXXX" + intact[4:])
    with pytest.raises(lex3d.dask.CompressError, match="shard_000.lex3dp") as e:
        lex3d.dask.ShardedPlaceDatabase(tmp_path / "db", client)
    assert e.value.code == 2 and "\n" not in str(e.value)
    # A missing shard.
    shard.write_bytes(intact)
    (tmp_path / "db" / "shard_001.lex3dp").unlink()
    r = run_command("place", "query", str(tmp_path / "db"), SCANS[0], "--scheduler", address)
    assert r.returncode == 2
    assert "shard_001.lex3dp" in r.stderr and len(r.stderr.strip().splitlines()) == 1, r.stderr
