"""The Python module: round trips of a real sample scan, the same bytes as the `lex3d`
command, determinism, and ValueError for bad arrays and bad data. Run by ctest
(python.tests), which sets PYTHONPATH to the built module, LEX3D_CLI and LEX3D_SAMPLES."""

import os
import pathlib
import subprocess
import tempfile

import numpy as np
import pytest
from scipy.spatial import cKDTree

import lex3d

SAMPLES = pathlib.Path(os.environ.get("LEX3D_SAMPLES", pathlib.Path(__file__).parents[2] / "samples"))
CLI = os.environ.get("LEX3D_CLI")


def read_bin(path, columns):
    """A .bin of float32 records (4 columns: KITTI x y z intensity; 3: x y z) as lex3d's
    reader gives it: points and intensity (or None), without the (0, 0, 0) no-return
    records and non-finite points."""
    raw = np.fromfile(path, dtype="<f4").reshape(-1, columns)
    keep = np.isfinite(raw[:, :3]).all(axis=1) & (raw[:, :3] != 0).any(axis=1)
    return raw[keep, :3], (raw[keep, 3] if columns == 4 else None)


@pytest.fixture(scope="module")
def kitti():
    return read_bin(SAMPLES / "kitti00_000000.bin", 4)


@pytest.fixture(scope="module")
def small():
    return read_bin(SAMPLES / "newer_college_00.bin", 3)[0]


def test_version_is_the_projects():
    assert lex3d.__version__.count(".") == 2
    assert all(part.isdigit() for part in lex3d.__version__.split("."))


def test_round_trip_of_a_real_scan_meets_the_bound_both_ways(kitti):
    points, _ = kitti
    assert len(points) > 100_000
    data = lex3d.compress(points, max_error=0.03)
    assert isinstance(data, bytes)
    assert 8 * len(data) / len(points) < 32
    back = lex3d.decompress(data)
    assert back.dtype == np.float32 and back.ndim == 2 and back.shape[1] == 3
    d_in, _ = cKDTree(back).query(points)
    d_out, _ = cKDTree(points).query(back)
    assert d_in.max() <= 0.03 * (1 + 1e-6)
    assert d_out.max() <= 0.03 * (1 + 1e-6)


@pytest.mark.skipif(not CLI, reason="LEX3D_CLI not set (run through ctest)")
@pytest.mark.parametrize("args", [["--max-error", "0.014"], ["--target-bpp", "5"],
                                  ["--iterations", "60", "--max-error", "none"], ["--max-error", "0.014", "--fast"],
                                  ["--max-error", "0.014", "--objective", "mse"]])
def test_same_bytes_as_the_command(args):
    scan = SAMPLES / "newer_college_00.bin"
    points, _ = read_bin(scan, 3)
    with tempfile.TemporaryDirectory() as tmp:
        out = pathlib.Path(tmp) / "out.lex3dm"
        subprocess.run([CLI, "compress", str(scan), "-o", str(out), *args], check=True, capture_output=True)
        expected = out.read_bytes()
    kwargs = {"max_error": 0.014} if args[0] == "--max-error" else \
             {"target_bpp": 5.0} if args[0] == "--target-bpp" else {"iterations": 60}
    if "--fast" in args:
        kwargs["fast"] = True
    if "--objective" in args:
        kwargs["objective"] = args[args.index("--objective") + 1]
    assert lex3d.compress(points, **kwargs) == expected
    assert lex3d.compress(points.astype(np.float64), **kwargs) == expected


def test_an_unknown_objective_is_refused(small):
    with pytest.raises(ValueError, match="objective must be 'bound' or 'mse'"):
        lex3d.compress(small, max_error=0.01, objective="psnr")


def test_intensity_is_kept_with_a_layer_and_reported_without(kitti):
    points, intensity = kitti
    data = lex3d.compress(points, intensity, max_error=0.05)
    back, fields = lex3d.decompress(data, attributes=True)
    assert set(fields) == {"intensity"}
    assert fields["intensity"].shape == (back.shape[0],)
    # every decoded intensity is one the scan has (lossless), and they vary as the scan's do
    assert np.isin(fields["intensity"], intensity).all()
    assert len(np.unique(fields["intensity"])) > 10
    with pytest.warns(UserWarning, match="intensity is not kept in this model file .*: 20000 values dropped"):
        lex3d.compress(points[:20000], intensity[:20000], iterations=5)


def test_deterministic_across_runs_and_threads(small):
    a = lex3d.compress(small, max_error=0.01, threads=1)
    assert a == lex3d.compress(small, max_error=0.01, threads=1)
    assert a == lex3d.compress(small, max_error=0.01, threads=2)
    assert a == lex3d.compress(np.ascontiguousarray(small[::-1][::-1]), max_error=0.01)


def test_learned_alphabet_is_reused_and_needed_to_decode(small):
    alphabet = lex3d.learn_alphabet([small], iterations=40)
    data = lex3d.compress(small, alphabet=alphabet)
    with pytest.raises(ValueError, match="alphabet"):
        lex3d.decompress(data)
    back = lex3d.decompress(data, alphabet=alphabet)
    assert back.shape[0] > 0
    with pytest.raises(ValueError, match="alphabet"):
        lex3d.compress(small, alphabet=b"not an alphabet")
    with pytest.raises(ValueError, match="words off uses no alphabet"):
        lex3d.compress(small, alphabet=alphabet, max_error=0.01)  # a layer: words off by default


def test_empty_scan_round_trips_to_an_empty_scan():
    back = lex3d.decompress(lex3d.compress(np.zeros((0, 3), np.float32), max_error=0.01))
    assert back.shape == (0, 3)


@pytest.mark.parametrize("bad, message", [
    (np.zeros((10, 4), np.float32), r"shape \(N, 3\), got \(10, 4\)"),
    (np.zeros((3,), np.float32), r"shape \(N, 3\), got \(3,\)"),
    (np.zeros((2, 3, 1), np.float32), r"shape \(N, 3\), got \(2, 3, 1\)"),
    (np.zeros((10, 3), np.int32), r"float32 or float64, got int32"),
    (np.zeros((10, 3), np.float16), r"float32 or float64, got float16"),
    (np.array([[0, 0, 1], [np.nan, 1, 2]], np.float32), r"row 1 is not finite"),
    (np.array([[0, 0, 1], [1, np.inf, 2]]), r"row 1 is not finite"),
    ([[0.0, 0.0, 1.0]], r"numpy array of shape \(N, 3\), got <class 'list'>"),
])
def test_bad_arrays_raise_value_error_naming_what_is_wrong(bad, message):
    with pytest.raises(ValueError, match=message):
        lex3d.compress(bad, max_error=0.01)


def test_bad_intensity_and_options_raise_value_error(small):
    with pytest.raises(ValueError, match=r"intensity must have shape"):
        lex3d.compress(small, np.zeros(3, np.float32), max_error=0.01)
    with pytest.raises(ValueError, match="max_error"):
        lex3d.compress(small, max_error=50.0)
    with pytest.raises(ValueError, match="words"):
        lex3d.compress(small, words="maybe")
    with pytest.raises(ValueError, match="clouds\\[1\\]"):
        lex3d.learn_alphabet([small, np.zeros((4, 2), np.float32)])


def test_an_integer_intensity_comes_back_in_its_dtype(kitti):
    """A uint16 intensity (a sensor's counts) is kept and given back as uint16 (model
    format 1.16 records its type); a 32-bit or complex one raises ValueError."""
    points, _ = kitti
    n = points.shape[0]
    counts = (np.arange(n) * 37 % 4096).astype(np.uint16)
    data = lex3d.compress(points, counts, max_error=0.014, keep_all_points=True)
    back, fields = lex3d.decompress(data, attributes=True)
    assert fields["intensity"].dtype == np.uint16
    assert np.array_equal(np.sort(fields["intensity"]), np.sort(counts))
    for bad in (counts.astype(np.uint32), counts.astype(np.complex64)):
        with pytest.raises(ValueError, match="intensity must be"):
            lex3d.compress(points, bad, max_error=0.014)


def test_a_drivers_ring_and_float32_time_code_as_the_capture_does():
    """The VLP-16 sample's turn as a driver gives it (points, intensity, ring, float32 time):
    the columns come from the firing times, the times cost a few hundred bytes and come back
    to the float32; a time of the wrong shape or dtype raises ValueError."""
    capture = lex3d.compress(str(SAMPLES / "vlp16_velodyne_example.pcap"), max_error=0.014, keep_all_points=True)
    points, fields = lex3d.decompress(capture, attributes=True)
    ring, time = fields["ring"], fields["time"].astype(np.float32)
    data, info = lex3d.compress(points, fields["intensity"], max_error=0.014, threads=1, report=True, ring=ring, time=time)
    assert info["attributes"] == ["ring", "intensity", "time"]
    without = lex3d.compress(points, fields["intensity"], max_error=0.014, threads=1, ring=ring, time=time,
                             drop_fields=["time"])
    assert 0 < len(data) - len(without) < 600
    back, got = lex3d.decompress(data, attributes=True)
    assert got["ring"].dtype == ring.dtype
    assert got["time"].dtype == np.float32  # as given (and as the capture's own)
    assert fields["time"].dtype == np.float32
    assert np.array_equal(np.sort(got["time"]), np.sort(time))
    # integer nanoseconds (ouster_ros's uint32 `t`) come back as such
    ns = np.round(time.astype(np.float64) * 1e9).astype(np.uint32)
    data_ns = lex3d.compress(points, max_error=0.014, threads=1, ring=ring, time=ns)
    _, got_ns = lex3d.decompress(data_ns, attributes=True)
    assert got_ns["time"].dtype == np.uint32
    assert np.array_equal(np.sort(got_ns["time"]), np.sort(ns))
    with pytest.raises(ValueError, match="time must have shape"):
        lex3d.compress(points, max_error=0.014, time=time[:-1])
    with pytest.raises(ValueError, match="time must be"):
        lex3d.compress(points, max_error=0.014, time=time.astype(np.complex64))
    with pytest.raises(ValueError, match="ring: value"):
        lex3d.compress(points, max_error=0.014, ring=np.full(len(points), 70000, dtype=np.int64))


def test_a_scans_stamp_and_frame_are_kept(small):
    """compress(stamp=) keeps a scan's stamp and frame (a ROS header's) in the file and
    lex3d.stamp reads them back; a capture keeps its turn's capture time; bad stamps raise."""
    assert lex3d.stamp(lex3d.compress(small, max_error=0.02)) is None
    data = lex3d.compress(small, max_error=0.02, stamp={"sec": 1700000000, "nsec": 250000000, "frame_id": "os_sensor"})
    assert lex3d.stamp(data) == {"sec": 1700000000, "nsec": 250000000, "frame_id": "os_sensor", "source": "message"}
    capture = lex3d.compress(str(SAMPLES / "vlp16_velodyne_example.pcap"), max_error=0.05)
    assert lex3d.stamp(capture) == {"sec": 1525347606, "nsec": 362040000, "frame_id": "", "source": "capture"}
    for bad, message in (({"nsec": 1}, "needs 'sec'"), ({"sec": -1}, "outside"), ({"sec": 1, "nsec": 10**9}, "outside"),
                         ({"sec": 1, "when": 2}, "unknown key"), ({"sec": 1.5}, "integer"), ((1, 2), "must be a dict")):
        with pytest.raises(ValueError, match=message):
            lex3d.compress(small, max_error=0.02, stamp=bad)
    with pytest.raises(ValueError):
        lex3d.stamp(data[: len(data) // 2])


def test_a_path_is_read_with_the_commands_read_options(small, tmp_path):
    """compress(path, metadata=, topic=, single_return=) reads as --metadata, --topic and
    --single-return do; they go with a path only; a missing or bad metadata file raises."""
    pcap = str(SAMPLES / "vlp16_velodyne_example.pcap")
    plain = lex3d.compress(pcap, max_error=0.05, threads=1)
    assert lex3d.compress(pcap, max_error=0.05, threads=1, single_return=True) == plain  # single return already
    with pytest.raises(ValueError, match="go with a path"):
        lex3d.compress(small, max_error=0.05, single_return=True)
    with pytest.raises(OSError, match="missing.json"):
        lex3d.compress(pcap, max_error=0.05, metadata=str(tmp_path / "missing.json"))
    # a calibration given is read: a VLP-16 db.xml whose lasers are not the packets' model's
    bad = tmp_path / "bad.xml"
    bad.write_text("<boost_serialization><DB><enabled_><count>16</count></enabled_></DB></boost_serialization>")
    with pytest.raises(ValueError, match="bad.xml"):
        lex3d.compress(pcap, max_error=0.05, metadata=str(bad))


def test_corrupt_and_truncated_files_raise_value_error(small):
    data = lex3d.compress(small, max_error=0.02)
    for n in (0, 3, len(data) // 2, len(data) - 1):
        with pytest.raises(ValueError):
            lex3d.decompress(data[:n])
    flipped = bytearray(data)
    flipped[len(data) // 2] ^= 0x40
    with pytest.raises(ValueError):
        lex3d.decompress(bytes(flipped))


PROFILE = pathlib.Path(__file__).parents[1] / "data" / "profile"


def test_a_sensor_profile_gives_the_laser_table_and_keeps_the_bound():
    scan = np.fromfile(PROFILE / "scene16.bin", dtype="<f4").reshape(-1, 4)
    points = scan[:, :3]
    data = lex3d.compress(points, max_error=0.014, sensor=PROFILE / "scene16.json")
    back = lex3d.decompress(data)
    d_in, _ = cKDTree(back).query(points)
    d_out, _ = cKDTree(points).query(back)
    assert max(d_in.max(), d_out.max()) <= 0.014 * (1 + 1e-6)
    if not CLI:
        return
    # the same bytes as the command with --sensor
    with tempfile.TemporaryDirectory() as tmp:
        out = pathlib.Path(tmp) / "s.lex3dm"
        subprocess.run([CLI, "compress", str(PROFILE / "scene16.bin"), "-o", str(out),
                        "--max-error", "0.014", "--sensor", str(PROFILE / "scene16.json"), "--drop-attributes"],
                       check=True, capture_output=True)
        assert out.read_bytes() == data


def test_a_bad_or_foreign_sensor_profile_raises_value_error(tmp_path):
    points = np.fromfile(PROFILE / "scene16.bin", dtype="<f4").reshape(-1, 4)[:, :3]
    bad = tmp_path / "bad.json"
    bad.write_text('{"range_step": 0.002, "lasers": [{"elevation_deg": "x"}]}')
    with pytest.raises(ValueError, match="bad.json: lasers\\[0\\].elevation_deg is string"):
        lex3d.compress(points, max_error=0.014, sensor=bad)
    other = tmp_path / "other.json"
    other.write_text('{"range_step": 0.002, "columns": 720, "lasers": [{"elevation_deg": -20}, {"elevation_deg": 7}]}')
    with pytest.raises(ValueError, match="other.json"):
        lex3d.compress(points, max_error=0.014, sensor=other)
    with pytest.raises(ValueError):
        lex3d.compress(points, sensor=PROFILE / "scene16.json")  # no residual layer


def write_las(path, xyz, classification, return_number, scan_angle):
    """A minimal LAS 1.2 file, point format 1 (no CRS records): mm steps, GPS times, and the
    fields a test reads back."""
    import struct
    n = len(xyz)
    scale = 0.001
    ints = np.round(xyz / scale).astype("<i4")
    header = bytearray(227)
    header[0:4] = b"LASF"
    header[24], header[25] = 1, 2
    header[26:58] = b"test".ljust(32, b"\0")
    struct.pack_into("<HIIBHI", header, 94, 227, 227, 0, 1, 28, n)
    struct.pack_into("<5I", header, 111, *[int((return_number == k).sum()) for k in range(1, 6)])
    struct.pack_into("<3d", header, 131, scale, scale, scale)
    struct.pack_into("<3d", header, 155, 0.0, 0.0, 0.0)
    hi, lo = xyz.max(axis=0), xyz.min(axis=0)
    struct.pack_into("<6d", header, 179, hi[0], lo[0], hi[1], lo[1], hi[2], lo[2])
    records = bytearray()
    for i in range(n):
        flags = int(return_number[i]) | (3 << 3)
        records += struct.pack("<3iHBBbBHd", *ints[i], 100 + i % 50, flags, int(classification[i]),
                               int(scan_angle[i]), 0, 7, 1000.0 + i * 1e-5)
    pathlib.Path(path).write_bytes(bytes(header) + bytes(records))


def test_las_point_fields_are_kept_by_name():
    rng = np.random.default_rng(5)
    n = 3000
    xyz = np.column_stack([rng.uniform(0, 50, n), rng.uniform(0, 50, n), rng.uniform(0, 2, n)])
    classification = np.where(xyz[:, 2] < 1.0, 2, 5)
    return_number = 1 + (np.arange(n) % 3)
    scan_angle = (np.arange(n) % 41) - 20
    with tempfile.TemporaryDirectory() as tmp:
        path = pathlib.Path(tmp) / "fields.las"
        write_las(path, xyz, classification, return_number, scan_angle)
        data, info = lex3d.compress(str(path), max_error=0.005, report=True)
        for name in ("classification", "return_number", "number_of_returns", "scan_angle_rank", "point_source_id"):
            assert name in info["attributes"], info
        back, fields = lex3d.decompress(data, attributes=True)
    # lossless integers, one per decoded point, the values the file holds
    assert fields["classification"].dtype == np.int32
    assert set(np.unique(fields["classification"])) == {2, 5}
    assert set(np.unique(fields["return_number"])) == {1, 2, 3}
    assert (fields["number_of_returns"] == 3).all()
    assert (fields["point_source_id"] == 7).all()
    assert fields["scan_angle_rank"].min() == -20 and fields["scan_angle_rank"].max() == 20
    assert len(fields["classification"]) == back.shape[0]


def test_pcd_fields_come_back_in_their_types():
    """A driver's PCD: uint16 reflectivity, uint32 range, float32 normals with a NaN. Each
    comes back as the numpy type the file had, every value as it was (no thinning)."""
    rng = np.random.default_rng(11)
    n = 4000
    az = np.linspace(0, 2 * np.pi, n, endpoint=False)
    r = 8 + 2 * np.sin(3 * az) + rng.normal(0, 0.01, n)
    dt = np.dtype([("x", "<f4"), ("y", "<f4"), ("z", "<f4"), ("reflectivity", "<u2"), ("range", "<u4"),
                   ("normal_x", "<f4")])
    a = np.zeros(n, dt)
    a["x"], a["y"], a["z"] = r * np.cos(az), r * np.sin(az), rng.uniform(-1, 1, n)
    a["reflectivity"] = rng.integers(0, 65536, n)
    a["range"] = np.round(r * 1000).astype(np.uint32)
    a["normal_x"] = np.cos(az)
    a["normal_x"][7] = np.nan
    header = (f"VERSION 0.7\nFIELDS x y z reflectivity range normal_x\nSIZE 4 4 4 2 4 4\nTYPE F F F U U F\n"
              f"COUNT 1 1 1 1 1 1\nWIDTH {n}\nHEIGHT 1\nPOINTS {n}\nDATA binary\n")
    with tempfile.TemporaryDirectory() as tmp:
        path = pathlib.Path(tmp) / "driver.pcd"
        path.write_bytes(header.encode() + a.tobytes())
        data = lex3d.compress(str(path), max_error=0.01, keep_all_points=True)
        back, fields = lex3d.decompress(data, attributes=True)
    assert fields["reflectivity"].dtype == np.uint16
    assert fields["range"].dtype == np.uint32
    assert fields["normal_x"].dtype == np.float32
    assert back.shape[0] == n
    # every point's values, matched by the points' unique reflectivity and range
    order_in = np.lexsort((a["range"], a["reflectivity"]))
    order_out = np.lexsort((fields["range"], fields["reflectivity"]))
    assert (fields["reflectivity"][order_out] == a["reflectivity"][order_in]).all()
    assert (fields["range"][order_out] == a["range"][order_in]).all()
    assert fields["normal_x"][order_out].tobytes() == a["normal_x"][order_in].tobytes()


def test_fields_given_as_arrays_round_trip_in_their_dtypes(kitti):
    """fields= keeps further per-point arrays (as a user's pipeline has them) with the layer,
    each back in its dtype; drop_fields leaves one out; bad fields raise ValueError."""
    points, intensity = kitti
    n = points.shape[0]
    label = (np.arange(n) % 7).astype(np.uint8)
    normal = (points[:, 0] / np.linalg.norm(points, axis=1)).astype(np.float32)
    stamp = (np.arange(n) % 1000 - 500).astype(np.int16)
    index = np.arange(n, dtype=np.uint32)
    data, info = lex3d.compress(points, intensity, max_error=0.014, keep_all_points=True, report=True,
                                fields={"label": label, "normal_x": normal, "stamp": stamp, "index": index})
    assert {"intensity", "label", "normal_x", "stamp", "index"} <= set(info["attributes"])
    back, fields = lex3d.decompress(data, attributes=True)
    assert back.shape[0] == n
    assert fields["label"].dtype == np.uint8 and fields["normal_x"].dtype == np.float32
    assert fields["stamp"].dtype == np.int16 and fields["index"].dtype == np.uint32
    # every point's values, found by its index: a permutation, each value with its point
    at = fields["index"]
    assert np.array_equal(np.sort(at), index)
    assert np.array_equal(fields["label"], label[at]) and np.array_equal(fields["stamp"], stamp[at])
    assert fields["normal_x"].tobytes() == normal[at].tobytes()
    assert np.abs(back - points[at]).max() <= 0.014 * 1.01
    dropped, info = lex3d.compress(points, intensity, max_error=0.014, report=True,
                                   fields={"label": label}, drop_fields=["label"])
    assert "label" in info["dropped_attributes"] and "label" not in info["attributes"]
    for bad, message in [({"label": label[:-1]}, "shape"), ({"a b": label}, "letters"),
                         ({"wide": points[:, 0].astype(np.float64) + 1e-9}, "float32 does not hold"),
                         ({"big": np.full(n, 2**31, np.uint32)}, "2\\^31"), ({"c": label.astype(np.complex64)}, "integer"),
                         ({"intensity": label}, "not a named field")]:
        with pytest.raises(ValueError, match=message):
            lex3d.compress(points, max_error=0.014, fields=bad)


def test_an_airborne_strip_keeps_its_order_through_the_acquisition_coding():
    # Pulses 10 us apart (write_las's GPS times) sweeping lines of 200 across the track, 1 m
    # on between lines, over rolling ground: the acquisition-order layer keeps the bound and
    # the decoded points come back in the order they were fired (their times rise).
    n = 4000
    k = np.arange(n)
    line, along = k // 200, k % 200
    x = np.where(line % 2 == 0, along, 199 - along) * 0.5
    y = line * 1.0 + 0.01 * along
    z = 3.0 * np.sin(x / 15.0) + 2.0 * np.cos(y / 9.0)
    xyz = np.column_stack([x, y, z])
    with tempfile.TemporaryDirectory() as tmp:
        path = pathlib.Path(tmp) / "strip.las"
        write_las(path, xyz, np.full(n, 2), np.ones(n, dtype=int), np.zeros(n, dtype=int))
        data = lex3d.compress(str(path), max_error=0.01, layer_coding="acquisition", keep_all_points=True)
        back, fields = lex3d.decompress(data, attributes=True)
        auto = lex3d.compress(str(path), max_error=0.01, keep_all_points=True)
    assert back.shape == (n, 3)
    assert back.dtype == np.float64  # a LAS file's true coordinates, not relative to the model's origin
    assert (np.diff(fields["time"]) > 0).all()
    # each decoded point within the bound of its input point (the same order), plus the file's
    # 1 mm step rounding the input on each axis
    assert np.linalg.norm(back - xyz, axis=1).max() <= 0.01 + 0.0005 * np.sqrt(3.0) + 1e-9
    assert len(auto) <= len(data)


def test_float64_utm_array_round_trips_within_the_bound():
    # UTM coordinates as float64: float32 would round them to 0.5 m; they are kept relative to
    # an origin the file stores and come back as float64 true coordinates within the bound.
    rng = np.random.default_rng(7)
    g = np.arange(0.0, 40.0, 0.25)
    x, y = np.meshgrid(g, g)
    x, y = x.ravel(), y.ravel()
    z = 1.5 * np.sin(x / 6.0) + 0.5 * np.cos(y / 4.0) + rng.normal(0.0, 0.003, x.size)
    utm = np.column_stack([x + 512345.678, y + 5403850.25, z + 121.5])
    data = lex3d.compress(utm, max_error=0.02, keep_all_points=True)
    back = lex3d.decompress(data)
    assert back.dtype == np.float64
    # every input point within E of a decoded one and the other way
    assert cKDTree(back).query(utm)[0].max() <= 0.02 + 1e-6
    assert cKDTree(utm).query(back)[0].max() <= 0.02 + 1e-6
    # a float32 array that already lost the precision is refused with a clear message
    with pytest.raises(ValueError, match="float32 resolution"):
        lex3d.compress(utm.astype(np.float32), max_error=0.02)
