"""The input files a lex3d.dask driver reads itself, before any work goes to the cluster."""

import os


def read_alphabet_file(path):
    """The bytes of the alphabet file `path` (formats/alphabet.md), checked to decode.

    Raises CompressError with exit code 3 when the file cannot be read (missing, a folder, no
    permission) and 2 when it reads but is not an alphabet file (empty, damaged, another format)."""
    import numpy as np

    import lex3d

    from ._compress import CompressError  # _compress imports this module
    path = os.fspath(path)
    try:
        with open(path, "rb") as f:
            data = f.read()
    except OSError as e:
        raise CompressError(3, f"{path}: cannot read the alphabet: {e.strerror or e}") from None
    if not data:
        raise CompressError(2, f"{path}: alphabet: the file is empty")
    try:  # an empty scan coded with it decodes the alphabet, and nothing else
        lex3d.compress(np.zeros((0, 3), np.float32), alphabet=data)
    except ValueError as e:
        raise CompressError(2, f"{path}: {e}") from None
    return data
