#!/usr/bin/env python3
"""Writes the seed corpus of the input-reader fuzz targets: tests/fuzz/readers/<format>/.

Small valid files of every layout each reader knows (so that mutations start from deep
inside the parser), built here from synthetic points so the corpus carries no third-party
data. Run from anywhere; the files are checked in, this script documents and rebuilds them:

    python3 tests/fuzz/make_reader_corpus.py
"""
import math
import os
import struct

HERE = os.path.dirname(os.path.abspath(__file__))
OUT = os.path.join(HERE, "readers")
FIXTURES = os.path.join(HERE, "..", "data", "io")


def points(n, seed=1):
    """n points on a slanted wall and a floor, a few metres from the origin."""
    out = []
    s = seed
    for i in range(n):
        s = (1103515245 * s + 12345) & 0x7FFFFFFF
        u = (s % 1000) / 1000.0
        a = 2 * math.pi * i / n
        if i % 2:
            out.append((4.0 * math.cos(a), 4.0 * math.sin(a), -1.5 + 3.0 * u))
        else:
            out.append((6.0 * u * math.cos(a), 6.0 * u * math.sin(a), -1.7))
    return out


def put(kind, name, data):
    d = os.path.join(OUT, kind)
    os.makedirs(d, exist_ok=True)
    with open(os.path.join(d, name), "wb") as f:
        f.write(data if isinstance(data, bytes) else data.encode())


def copy_fixture(kind, name):
    with open(os.path.join(FIXTURES, name), "rb") as f:
        put(kind, name, f.read())


def lzf_literals(raw):
    """An LZF stream of literal runs only (valid for any decoder)."""
    out = bytearray()
    for i in range(0, len(raw), 32):
        run = raw[i:i + 32]
        out.append(len(run) - 1)
        out += run
    return bytes(out)


def pcd():
    pts = points(24)
    head = ("# .PCD v0.7\nVERSION 0.7\nFIELDS x y z intensity\nSIZE 4 4 4 4\nTYPE F F F F\nCOUNT 1 1 1 1\n"
            "WIDTH 24\nHEIGHT 1\nVIEWPOINT 0 0 0 1 0 0 0\nPOINTS 24\nDATA ascii\n")
    put("pcd", "ascii_intensity.pcd", head + "".join("%.4f %.4f %.4f %d\n" % (x, y, z, i) for i, (x, y, z) in enumerate(pts)))
    # binary: x y z rgb ring time (float32 ×4, u16, f64)
    head = ("# .PCD v0.7\nVERSION 0.7\nFIELDS x y z rgb ring time\nSIZE 4 4 4 4 2 8\nTYPE F F F U U F\n"
            "COUNT 1 1 1 1 1 1\nWIDTH 8\nHEIGHT 3\nVIEWPOINT 0.5 0 0 1 0 0 0\nPOINTS 24\nDATA binary\n")
    body = b"".join(struct.pack("<fffIHd", x, y, z, (i * 40) << 16 | (255 - i * 5) << 8 | i, i % 3, 0.001 * i)
                    for i, (x, y, z) in enumerate(pts))
    put("pcd", "binary_rgb_ring_time.pcd", head.encode() + body)
    # binary_compressed: fields stored one after another, LZF
    head = ("# .PCD v0.7\nVERSION 0.7\nFIELDS x y z\nSIZE 4 4 4\nTYPE F F F\nCOUNT 1 1 1\nWIDTH 24\nHEIGHT 1\n"
            "VIEWPOINT 0 0 0 1 0 0 0\nPOINTS 24\nDATA binary_compressed\n")
    raw = b"".join(struct.pack("<%df" % len(pts), *[p[k] for p in pts]) for k in range(3))
    z = lzf_literals(raw)
    put("pcd", "binary_compressed.pcd", head.encode() + struct.pack("<II", len(z), len(raw)) + z)
    copy_fixture("pcd", "organized_nan.pcd")
    copy_fixture("pcd", "extra_fields.pcd")


def ply():
    pts = points(16)
    head = ("ply\nformat binary_little_endian 1.0\ncomment lex3d fuzz seed\nelement vertex 16\nproperty float x\n"
            "property float y\nproperty float z\nproperty uchar red\nproperty uchar green\nproperty uchar blue\n"
            "property float intensity\nproperty double time\nend_header\n")
    body = b"".join(struct.pack("<fffBBBfd", x, y, z, i * 9, 200 - i, 7, 0.5 * i, 1e-3 * i)
                    for i, (x, y, z) in enumerate(pts))
    put("ply", "binary_le_rgb.ply", head.encode() + body)
    head = "ply\nformat ascii 1.0\nelement vertex 16\nproperty float x\nproperty float y\nproperty float z\nend_header\n"
    put("ply", "ascii.ply", head + "".join("%.3f %.3f %.3f\n" % p for p in pts))
    for f in ("ascii_faces.ply", "big_endian.ply", "extra_props_double.ply"):
        copy_fixture("ply", f)


def binaries():
    pts = points(20)
    put("kitti", "kitti.bin", b"".join(struct.pack("<ffff", x, y, z, 0.01 * i) for i, (x, y, z) in enumerate(pts))
        + struct.pack("<ffff", 0, 0, 0, 0))
    put("binxyz", "xyz.bin", b"".join(struct.pack("<fff", *p) for p in pts))


def text():
    pts = points(12)
    put("xyz", "plain.xyz", "".join("%.3f %.3f %.3f\n" % p for p in pts))
    put("xyz", "named_columns.xyz", "x y z intensity\n" + "".join("%.3f,%.3f,%.3f,%d\n" % (x, y, z, i)
                                                            for i, (x, y, z) in enumerate(pts)))
    copy_fixture("xyz", "mixed.xyz")
    put("uos", "scan.3d", "".join("%.1f %.1f %.1f\n" % (100 * -y, 100 * z, 100 * x) for x, y, z in points(12))
        + "0 0 3270\n")
    copy_fixture("uos", "tiny.3d")
    put("poses", "poses.txt", "1 0 0 0 0 1 0 0 0 0 1 0\n1 0 0 0.5 0 1 0 0 0 0 1 0\n"
        "0.99500417 -0.09983342 0 1 0.09983342 0.99500417 0 0.1 0 0 1 0\n")


def las_header(version_minor, fmt, record_len, n, header_size, offset_to_points, vlrs, mins, maxs):
    h = bytearray()
    h += b"LASF" + struct.pack("<HH", 0, 0) + struct.pack("<IHH8s", 0, 0, 0, b"\0" * 8)
    h += struct.pack("<BB", 1, version_minor)
    h += b"lex3d fuzz seed".ljust(32, b"\0") + b"make_reader_corpus".ljust(32, b"\0")
    h += struct.pack("<HH", 1, 2026)
    h += struct.pack("<HIIBH", header_size, offset_to_points, vlrs, fmt, record_len)
    h += struct.pack("<I", n if fmt < 6 else 0) + struct.pack("<5I", n if fmt < 6 else 0, 0, 0, 0, 0)
    h += struct.pack("<3d", 0.001, 0.001, 0.001) + struct.pack("<3d", 500000.0, 5000000.0, 100.0)
    h += struct.pack("<6d", maxs[0], mins[0], maxs[1], mins[1], maxs[2], mins[2])
    if version_minor >= 3:
        h += struct.pack("<Q", 0)  # start of waveform data
    if version_minor >= 4:
        h += struct.pack("<QIQ", 0, 0, n) + struct.pack("<15Q", n, *([0] * 14))
    assert len(h) == header_size, (len(h), header_size)
    return bytes(h)


def las():
    pts = [(500000.0 + x, 5000000.0 + y, 100.0 + z) for x, y, z in points(16)]
    mins = [min(p[k] for p in pts) for k in range(3)]
    maxs = [max(p[k] for p in pts) for k in range(3)]
    q = [tuple(int(round((p[k] - (500000.0, 5000000.0, 100.0)[k]) / 0.001)) for k in range(3)) for p in pts]
    # 1.2, format 3 (GPS time + RGB), no VLR
    recs = b"".join(struct.pack("<iiiHBBbBHdHHH", X, Y, Z, 100 + i, 0x11, 2, 0, 0, 0, 1e5 + i, 256 * i, 1000, 65535)
                    for i, (X, Y, Z) in enumerate(q))
    put("las", "las12_format3.las", las_header(2, 3, 34, len(q), 227, 227, 0, mins, maxs) + recs)
    # 1.4, format 6 with a WKT CRS VLR
    wkt = b'PROJCS["WGS 84 / UTM zone 10N",UNIT["metre",1]]\0'
    vlr = struct.pack("<H16sHH32s", 0, b"LASF_Projection".ljust(16, b"\0"), 2112, len(wkt), b"WKT".ljust(32, b"\0")) + wkt
    recs = b"".join(struct.pack("<iiiHBBBbHHd", X, Y, Z, 50 + i, 0x11, 0x10, 2, 0, 0, 0, 2e5 + i)
                    for i, (X, Y, Z) in enumerate(q))
    head = bytearray(las_header(4, 6, 30, len(q), 375, 375 + len(vlr), 1, mins, maxs))
    struct.pack_into("<H", head, 6, 1 << 4)  # global encoding: WKT
    put("las", "las14_format6_wkt.las", bytes(head) + vlr + recs)


def pcap_file(payloads, period_us, port):
    out = bytearray(struct.pack("<IHHiIII", 0xA1B2C3D4, 2, 4, 0, 0, 65535, 1))  # Ethernet
    t = 1_700_000_000 * 1_000_000
    for k, p in enumerate(payloads):
        udp = struct.pack(">HHHH", port, port, 8 + len(p), 0) + p
        ip = struct.pack(">BBHHHBBH4s4s", 0x45, 0, 20 + len(udp), k & 0xFFFF, 0, 64, 17, 0,
                         bytes([192, 168, 1, 201]), bytes([192, 168, 1, 100])) + udp
        frame = b"\xff" * 6 + b"\x00\x11\x22\x33\x44\x55" + b"\x08\x00" + ip
        ts = t + int(k * period_us)
        out += struct.pack("<IIII", ts // 1_000_000, ts % 1_000_000, len(frame), len(frame)) + frame
    return bytes(out)


def velodyne():
    """VLP-16 packets, strongest return, azimuth advancing 0.2° a firing over 1.2 turns."""
    packets = []
    az = 35000  # start near the wrap so a complete turn is seen early
    t_us = 0
    for k in range(24):
        p = bytearray()
        for b in range(12):
            p += struct.pack("<HH", 0xEEFF, az % 36000)
            for f in range(32):
                d = int((5.0 + 0.5 * math.sin(0.01 * (az + f))) / 0.002) if (f + k) % 7 else 0
                p += struct.pack("<HB", d, 40 + f)
            az += 300
        p += struct.pack("<IBB", t_us, 0x37, 0x22)
        t_us += 1327
        packets.append(bytes(p))
    put("pcap", "vlp16.pcap", pcap_file(packets, 1327.104, 2368))
    # VLP-32C, dual return: each firing twice in a pair of blocks with one azimuth (the last
    # return, then the strongest, 10 cm farther on every fifth laser), packets twice as often.
    packets = []
    az = 35500
    t_us = 0
    for k in range(40):
        p = bytearray()
        for b in range(6):
            last, strongest = bytearray(), bytearray()
            for f in range(32):
                d = int((8.0 + 0.5 * math.cos(0.01 * (az + 7 * f))) / 0.004) if (f + k) % 9 else 0
                last += struct.pack("<HB", d, 20 + f)
                strongest += struct.pack("<HB", d + 25 if d and f % 5 == 0 else d, 60 + f)
            p += struct.pack("<HH", 0xEEFF, az % 36000) + last
            p += struct.pack("<HH", 0xEEFF, az % 36000) + strongest
            az += 200
        p += struct.pack("<IBB", t_us, 0x39, 0x28)
        t_us += 332
        packets.append(bytes(p))
    put("pcap", "vlp32c_dual.pcap", pcap_file(packets, 331.776, 2368))


def hdl64():
    """HDL-64E packets (upper and lower blocks of one azimuth, no factory byte) over 1.2
    turns, 3.6° a firing; read with the calibration fuzz_readers.hpp gives (hdl64e)."""
    packets = []
    az = 100
    for k in range(20):
        p = bytearray()
        for pair in range(6):
            for bank, flag in ((0, 0xEEFF), (1, 0xDDFF)):
                p += struct.pack("<HH", flag, az % 36000)
                for f in range(32):
                    d = int((6.0 + 2.0 * math.sin(0.0005 * az + 0.2 * f + bank)) / 0.002) if (f + pair + k) % 11 else 0
                    p += struct.pack("<HB", d, 10 + f + 32 * bank)
            az += 360
        p += struct.pack("<IBB", k * 288, 0xA5, k & 255)
        packets.append(bytes(p))
    put("hdl64", "hdl64e_s2.pcap", pcap_file(packets, 288.0, 2368))


def ouster():
    """LEGACY packets of the 16-beam sensor in fuzz_readers.hpp's metadata (a 64-column
    azimuth window: 4 packets a frame), two frames and the start of a third."""
    packets = []
    for k in range(9):
        frame, first = 7 + k // 4, 16 * (k % 4)
        p = bytearray()
        for c in range(16):
            m = first + c
            p += struct.pack("<QHHI", 10_000_000 + 97_656 * (64 * frame + m), m, frame, m * 88)
            for r in range(16):
                rng = 4000 + 10 * r + 3 * m if (r + c) % 9 else 0
                p += struct.pack("<IHHHH", rng, 30 + r, 200, 100, 0)
            p += struct.pack("<I", 0xFFFFFFFF)
        packets.append(bytes(p))
    put("ouster", "os1_16_legacy_window.pcap", pcap_file(packets, 1562.5, 7502))


if __name__ == "__main__":
    pcd()
    ply()
    binaries()
    text()
    las()
    velodyne()
    ouster()
    hdl64()
    for k in sorted(os.listdir(OUT)):
        print(k, sorted(os.listdir(os.path.join(OUT, k))))
