"""lex3d: compress lidar scans with a learned alphabet of local 3D structures and a
bounded-error residual layer, and recognise places from the compressed form.

    data = lex3d.compress(points, max_error=0.014)   # points: (N, 3) float32/float64, metres
    back = lex3d.decompress(data)                    # (M, 3) float32
    db = lex3d.PlaceDatabase.open("map.lex3dp")      # db.query(points) -> matches
    for scan in lex3d.scans("drive.pcap"):            # a capture's turns, a bag's scans, one at a time
        data = lex3d.compress(scan, max_error=0.02)

The bytes are those `lex3d compress` writes for the same settings (formats/model.md).
lex3d.dask (imported on its own) runs the same work on a Dask cluster.
"""

from ._lex3d import PlaceDatabase, Scan, __version__, compress, decompress, holds_scans, learn_alphabet, scans, stamp

__all__ = ["compress", "decompress", "learn_alphabet", "scans", "holds_scans", "Scan", "stamp", "PlaceDatabase",
           "__version__"]
