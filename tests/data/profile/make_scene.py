#!/usr/bin/python3
"""Writes scene16.bin (KITTI layout: float32 x y z intensity) and scene16.json: a synthetic
16-laser spinning lidar (elevations -15 ... 15 degrees in 2 degree steps, interleaved as a
VLP-16's, fired 2.304 us apart, 2 mm range steps, 720 columns a turn) in a room 30 x 40 m
with a floor 1.6 m below the sensor, points in firing order. Used by tests/cli/cli_tests.cmake
for `lex3d compress --sensor`."""
import json
import math
import os
import struct

here = os.path.dirname(os.path.abspath(__file__))
columns, step, rate = 720, 0.002, 10.0
lasers = [{"elevation_deg": float(-15 + l if l % 2 == 0 else l), "azimuth_deg": 0.0, "fire_us": 2.304 * l,
           "z_offset": 0.0, "horiz_offset": 0.0} for l in range(16)]
with open(os.path.join(here, "scene16.json"), "w") as f:
    json.dump({"sensor": "synthetic 16-laser", "columns": columns, "range_step": step, "lasers": lasers}, f, indent=1)
out = bytearray()
for c in range(columns):
    for l, b in enumerate(lasers):
        # clockwise spin: the beam's azimuth falls with the column and the firing time
        az = -math.radians(360.0 * c / columns + 360.0 * rate * b["fire_us"] * 1e-6)
        el = math.radians(b["elevation_deg"])
        dx, dy, dz = math.cos(az) * math.cos(el), math.sin(az) * math.cos(el), math.sin(el)
        t = 1e9
        if dz < -1e-6:
            t = min(t, -1.6 / dz)
        if abs(dx) > 1e-9:
            t = min(t, (20.0 if dx > 0 else -10.0) / dx)
        if abs(dy) > 1e-9:
            t = min(t, (15.0 if dy > 0 else -25.0) / dy)
        if t * dz > 3.0:
            continue  # above the walls: no return
        r = round(t / step) * step
        out += struct.pack("<4f", r * dx, r * dy, r * dz, float(l))
with open(os.path.join(here, "scene16.bin"), "wb") as f:
    f.write(out)
