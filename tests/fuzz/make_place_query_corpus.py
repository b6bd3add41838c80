#!/usr/bin/env python3
"""Writes the seed corpus of the prepared place query fuzz target: tests/fuzz/readers/placequery/.

Prepared queries (formats/place_db.md §7, PlaceDatabase.prepare_query) of the sample scans
against a database of the KITTI sample with the default storage: one without a pose, one with a
world pose (the SCAN payload's pose flag). The files are checked in; this script documents and
rebuilds them (with the built module on PYTHONPATH, e.g. build/python/package):

    PYTHONPATH=build/python/package python3 tests/fuzz/make_place_query_corpus.py
"""
import os

import numpy as np

import lex3d

HERE = os.path.dirname(os.path.abspath(__file__))
OUT = os.path.join(HERE, "readers", "placequery")
SAMPLES = os.path.join(HERE, "..", "..", "samples")


def main():
    os.makedirs(OUT, exist_ok=True)
    db = lex3d.PlaceDatabase.build([os.path.join(SAMPLES, "kitti00_000000.bin")], iterations=40, seed=1)
    pose = np.eye(4)
    pose[:3, 3] = [12.5, -3.0, 0.4]
    for name, scan, kw in (("newer_college_00.lex3dq", "newer_college_00.bin", {}),
                           ("room_scan1_posed.lex3dq", "room_scan1.pcd", {"pose": pose})):
        data = db.prepare_query(os.path.join(SAMPLES, scan), **kw)
        with open(os.path.join(OUT, name), "wb") as f:
            f.write(data)
        print(f"{name}: {len(data)} bytes")


if __name__ == "__main__":
    main()
