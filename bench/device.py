"""``python -m bench.device``: thread scaling on the many-core device machine (bench/sections/device.py)."""

import sys

from .sections.device import main

if __name__ == "__main__":
    sys.exit(main())
