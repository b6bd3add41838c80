"""lex3d on a Dask cluster: many scans compressed with one shared alphabet, and that alphabet
learned over many scans.

    python3 -m lex3d.dask compress SCANS_DIR -o out/drive.lex3dm --max-error 0.02 --words on
    python3 -m lex3d.dask compress @files.txt -o out/d.lex3dm --alphabet a.lex3da --scheduler tcp://host:8786
    python3 -m lex3d.dask learn SCANS_DIR -o fleet.lex3da --seed 1
    python3 -m lex3d.dask place build SCANS_DIR -o places/ --shards 4
    python3 -m lex3d.dask place query places/ query.bin

From Python:

    from dask.distributed import Client
    import lex3d.dask
    summary = lex3d.dask.compress(["a.bin", "b.bin"], "out/x.lex3dm", client=Client(...),
                                  alphabet="a.lex3da")

The alphabet is given or learned once (on one worker), sent to every worker once under its
content hash, and each worker codes whole scans: the files are byte for byte those of
`lex3d compress SCANS --alphabet A -o OUT` (the same names: OUT_000.lex3dm, ...). A manifest
(JSON lines) lists every scan with its file, bytes, bits a point and error bound, or the error
that stopped it; the other scans complete. Each file is written to a temporary name and
renamed, so a worker that dies leaves no partial file, and a retried scan whose file is already
there with the same bytes is not written again.

learn keeps each worker's share of the scans prepared in a Dask actor; the driver runs the BIC
decisions on the per-scan likelihood changes the workers return, and the alphabet is byte for
byte that of `lex3d learn SCANS -o A --seed S` (lex3d.dask._learn).
"""

from ._compress import CompressError, compress, expand_inputs, numbered_output
from ._learn import learn
from ._place import ShardedPlaceDatabase
from ._place import build as build_place_shards
from ._worker import worker_malloc

__all__ = ["compress", "learn", "build_place_shards", "ShardedPlaceDatabase", "CompressError", "expand_inputs",
           "numbered_output", "worker_malloc"]
