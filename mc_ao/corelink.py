"""Finds the bundled core library, whichever way the add-on was loaded.

Installed as an extension, this package is ``bl_ext.<repo>.mc_ao.mc_ao`` and the core is its sibling
``bl_ext.<repo>.mc_ao.core``; loaded from a checkout with the repository root on ``sys.path`` (tests,
scripts/bake_ao.py), this package is the top-level ``mc_ao`` and the core is the top-level ``core``.
The core is imported on first use only: it pulls in numpy and embreex, which registering the add-on
does not need.
"""

import importlib

_PARENT = __package__.rpartition(".")[0]
CORE_NAME = f"{_PARENT}.core" if _PARENT else "core"


def load(submodule=None):
    """Import and return the core package, or one of its submodules (``load("imageio")``)."""
    return importlib.import_module(CORE_NAME if submodule is None else f"{CORE_NAME}.{submodule}")
