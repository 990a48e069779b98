"""``python -m bench``: the whole benchmark in one run (bench/harness/run.py)."""

import sys

from .harness.run import main

sys.exit(main())
