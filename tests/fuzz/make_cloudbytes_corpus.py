#!/usr/bin/env python3
"""Writes the seeds of fuzz_reader_cloudbytes (tests/fuzz/readers/cloudbytes/): the clouds of
some reader seeds as lex3d.Scan pickles them (codec::cloud_to_bytes), so that every member
(named fields, sources, the georeference with its CRS records, an Ouster turn's laser table
and stamp) is in some seed.

usage: PYTHONPATH=build/python/package make_cloudbytes_corpus.py OUT_DIR
"""
import os
import pathlib
import sys

import lex3d

HERE = pathlib.Path(__file__).parent
SOURCES = {
    "pcd_typed_fields": HERE / "readers/pcd/binary_typed_fields.pcd",
    "pcd_rgb_ring_time": HERE / "readers/pcd/binary_rgb_ring_time.pcd",
    "pcd_organised": HERE / "readers/pcd/organized_nan.pcd",
    "las14_wkt": HERE / "readers/las/las14_format6_wkt.las",
    "las14_extra_bytes": HERE / "readers/las/las14_extra_bytes.las",
}


def main(out):
    os.makedirs(out, exist_ok=True)
    for name, path in SOURCES.items():
        (scan,) = lex3d.scans(path)
        _, blob = scan.__getstate__()
        pathlib.Path(out, name + ".l3dc").write_bytes(blob)
    # a raw capture's turn: laser table, stamp, columns, times (the reader seed's capture)
    capture = HERE / "readers/pcap/vlp16.pcap"
    for scan in lex3d.scans(capture):
        _, blob = scan.__getstate__()
        pathlib.Path(out, "vlp16_turn.l3dc").write_bytes(blob)
        break

if __name__ == "__main__":
    main(sys.argv[1] if len(sys.argv) > 1 else str(HERE / "readers/cloudbytes"))
