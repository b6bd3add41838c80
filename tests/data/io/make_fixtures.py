#!/usr/bin/env python3
"""Regenerates the small io test fixtures in this directory (deterministic)."""
import math
import os
import struct

HERE = os.path.dirname(os.path.abspath(__file__))


def write(name, data):
    with open(os.path.join(HERE, name), "wb") as f:
        f.write(data)


# Big-endian PLY: float x y z, float intensity, uchar rgb; a face element after the vertices.
verts = [(1.5, -2.25, 3.0, 0.5, 10, 20, 30),
         (-0.125, 4.0, 1e-3, 1.0, 255, 0, 7),
         (100.0, 200.5, -300.25, 0.0, 1, 2, 3)]
hdr = ("ply\nformat binary_big_endian 1.0\ncomment big-endian fixture\n"
       "element vertex 3\nproperty float x\nproperty float y\nproperty float z\n"
       "property float intensity\nproperty uchar red\nproperty uchar green\nproperty uchar blue\n"
       "element face 1\nproperty list uchar int vertex_indices\nend_header\n").encode()
body = b"".join(struct.pack(">ffffBBB", *v) for v in verts)
body += struct.pack(">Biii", 3, 0, 1, 2)
write("big_endian.ply", hdr + body)

# Little-endian PLY with double coordinates, extra properties, an element before the
# vertices (with a list) and faces after.
hdr = ("ply\nformat binary_little_endian 1.0\ncomment extra properties, double coords\n"
       "obj_info made by make_fixtures.py\n"
       "element camera 2\nproperty float view_px\nproperty list uchar float params\n"
       "element vertex 4\nproperty double x\nproperty double y\nproperty double z\n"
       "property float nx\nproperty float ny\nproperty float nz\nproperty ushort label\n"
       "property float scalar_intensity\nproperty int16 extra\n"
       "element face 2\nproperty list uchar int vertex_indices\nend_header\n").encode()
cams = struct.pack("<fB", 1.0, 2) + struct.pack("<ff", 3.0, 4.0) + struct.pack("<fB", 5.0, 0)
dverts = [(0.1, 0.2, 0.3), (-1.0, -2.0, -3.0), (12345.678, 0.0, -0.5), (float("nan"), 1.0, 2.0)]
body = b"".join(struct.pack("<dddfffHfh", x, y, z, 0.0, 0.0, 1.0, i, 0.25 * i, -i)
                for i, (x, y, z) in enumerate(dverts))
body += struct.pack("<Biii", 3, 0, 1, 2) + struct.pack("<Biiii", 4, 0, 1, 2, 3)
write("extra_props_double.ply", hdr + cams + body)

# ASCII PLY with comments, normals, and a face element.
txt = """ply
format ascii 1.0
comment ascii fixture
element vertex 3
property float x
property float y
property float z
property float nx
property float ny
property float nz
element face 1
property list uchar int vertex_indices
end_header
0 0 0 0 0 1
1 0 0 0 0 1
0 1.5 -2 0 0 1
3 0 1 2
"""
write("ascii_faces.ply", txt.encode())

# ASCII PCD with extra fields (intensity, normals, curvature).
txt = """# .PCD v0.7 - Point Cloud Data file format
VERSION 0.7
FIELDS x y z intensity normal_x normal_y normal_z curvature
SIZE 4 4 4 4 4 4 4 4
TYPE F F F F F F F F
COUNT 1 1 1 1 1 1 1 1
WIDTH 4
HEIGHT 1
VIEWPOINT 0 0 0 1 0 0 0
POINTS 4
DATA ascii
1 2 3 0.5 0 0 1 0.01
-1.5 2.25 -3 1 0 1 0 0.02
0.1 0.2 0.3 7 1 0 0 0
nan nan nan 0 0 0 0 0
"""
write("extra_fields.pcd", txt.encode())

# Organized binary PCD (4 x 3) with NaN holes and mixed field types:
# x y z F4, a 4-byte padding field "_", intensity U2, rgb F4 (packed), t F8, normal F4 x3 (COUNT 3).
hdr = ("# .PCD v0.7 - Point Cloud Data file format\nVERSION 0.7\n"
       "FIELDS x y z _ intensity rgb t normal\nSIZE 4 4 4 1 2 4 8 4\nTYPE F F F U U F F F\n"
       "COUNT 1 1 1 4 1 1 1 3\nWIDTH 4\nHEIGHT 3\nVIEWPOINT 0 0 0 1 0 0 0\nPOINTS 12\n"
       "DATA binary\n").encode()
body = b""
nan = float("nan")
for r in range(3):
    for c in range(4):
        i = r * 4 + c
        hole = (i % 5 == 2)
        x, y, z = (nan, nan, nan) if hole else (c * 0.5, r * -0.25, 1.0 + i)
        rgb = struct.unpack("<f", struct.pack("<I", 0xFF000000 | (i << 16) | (2 * i << 8) | 3 * i))[0]
        body += struct.pack("<fff4sHfdfff", x, y, z, b"\0\0\0\0", 100 + i, rgb, i * 0.001, 0, 0, 1)
write("organized_nan.pcd", hdr + body)

# Text x y z with comments, blank lines, commas and tabs.
txt = "# a comment\n\n1.5 2.5 3.5\n-1,-2,-3\n\t4\t5\t6\n  # indented comment\n7 , 8 , 9\r\n"
write("mixed.xyz", txt.encode())

# A tiny 3DTK scan (cm, left-handed) with one no-return reading, and its pose.
txt = "100 0 0\n0 200 0\n0 0 300\n3276.3 0 0\n10 20 30\n"
write("tiny.3d", txt.encode())
write("tiny.pose", b"100 200 300\n0 90 0\n")

# ouster_fw3_layout_OS-1-32-G.json: the metadata of ../shared/data/ouster/OS-1-32-G_v2.1.1_1024x10.json
# (Ouster SDK test data, BSD-3-Clause, Copyright (c) 2018-2026 Ouster, Inc.) rearranged, values
# unchanged, into the fw 3 nested layout; made once with:
#   d = json.load(open(src)); n = d["lidar_origin_to_beam_origin_mm"]
#   json.dump({"beam_intrinsics": {"beam_altitude_angles": d["beam_altitude_angles"],
#                                  "beam_azimuth_angles": d["beam_azimuth_angles"],
#                                  "lidar_origin_to_beam_origin_mm": n,
#                                  "beam_to_lidar_transform": [1,0,0,n, 0,1,0,0, 0,0,1,0, 0,0,0,1]},
#              "lidar_intrinsics": {"lidar_to_sensor_transform": d["lidar_to_sensor_transform"]},
#              "lidar_data_format": d["data_format"],
#              "sensor_info": {"prod_line": d["prod_line"], "prod_sn": d["prod_sn"]},
#              "config_params": {"udp_profile_lidar": "LEGACY", "lidar_mode": d["lidar_mode"]}},
#             open(out, "w"), indent=1)

# hdl64e_calibration.yaml: the ROS driver's calibration layout for a made-up HDL-64E (the
# values tests/fuzz/fuzz_readers.hpp's hdl64_calibration() gives the `hdl64` fuzz target),
# with which tests/fuzz/readers/hdl64/hdl64e_s2.pcap decodes (the CLI tests use both).
import math
lines = ["distance_resolution: 0.002", "lasers:"]
for l in range(64):
    k = l if l < 32 else l - 32
    vert = (2.0 - 0.34 * (k * 7 % 32) if l < 32 else -8.8 - 0.5 * (k * 5 % 32)) * 3.14159265358979 / 180
    rot = 8.0 * math.sin(1.7 * l + 0.3) * 3.14159265358979 / 180
    dist = 1.2 + 0.005 * (l * 13 % 40)
    lines.append("- {laser_id: %d, rot_correction: %.12g, vert_correction: %.12g, dist_correction: %.6g, "
                 "dist_correction_x: %.6g, dist_correction_y: %.6g, vert_offset_correction: %.6g, "
                 "horiz_offset_correction: %.6g, two_pt_correction_available: %s}"
                 % (l, rot, vert, dist, dist + 0.03, dist - 0.02, 0.215 if l < 32 else 0.16,
                    0.026 if l % 2 == 0 else -0.026, "true" if l % 2 == 0 else "false"))
write("hdl64e_calibration.yaml", ("\n".join(lines) + "\n").encode())
