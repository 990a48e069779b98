#!/usr/bin/env python3
"""Bake AO of an asset library: every .blend file of a TOML manifest, one process per file.

    python scripts/bake_batch.py MANIFEST --output DIR [--runner local|dask] [--workers N]
                                 [--scheduler ADDRESS] [--force] [--blender PATH|auto|bpy]

Writes DIR/<blend file stem>/<object>_AO.<ext>, DIR/mc_ao_batch.json (every task's status, seconds,
rays, files and error), a progress bar and a table; exits with 0 only when every task succeeded.
--runner flamenco and --runner openjd hand the same tasks to a render farm. See docs/batch.md
and mc_ao_batch/.
"""

import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent
if str(ROOT) not in sys.path:
    sys.path.insert(0, str(ROOT))

from mc_ao_batch.cli import main  # noqa: E402

if __name__ == "__main__":
    sys.exit(main())
