#!/usr/bin/env python3
"""Bake ambient occlusion of objects in a .blend file into image files, without the UI.

    blender -b -q scene.blend --python scripts/bake_ao.py -- --objects A B --samples 128 --resolution 1024 --output out/
    python scripts/bake_ao.py scene.blend --objects A B --samples 128 --resolution 1024 --output out/

The options, exit status and summary are mc_ao.cli's (``--help``); this file only finds the package.
"""

import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent
if str(ROOT) not in sys.path:
    sys.path.insert(0, str(ROOT))

from mc_ao import cli  # noqa: E402
from mc_ao_batch import lifeline  # noqa: E402

if __name__ == "__main__":
    lifeline.from_environment()  # a batch task's bake ends with its guard process, however that ends
    sys.exit(cli.main())
