"""python3 -m lex3d.dask: see lex3d.dask.cli."""

import sys

from .cli import main

if __name__ == "__main__":
    sys.exit(main())
