"""``python -m ehm_drake.sweep SPEC --out DIR ...`` (same as ``ehm-drake sweep``)."""

import sys

from .command import main

if __name__ == "__main__":  # pragma: no cover
    sys.exit(main())
