"""Finds the bundled core library, whichever way the add-on was loaded.

Installed as an extension, this package is ``bl_ext.<repo>.mc_ao.mc_ao`` and the core is its sibling
``bl_ext.<repo>.mc_ao.core``; loaded from a checkout with the repository root on ``sys.path`` (tests,
scripts/bake_ao.py), this package is the top-level ``mc_ao`` and the core is the top-level ``core``.
The core is imported on first use only: it pulls in numpy and embreex, which registering the add-on
does not need.
"""

import importlib
import importlib.util

_PARENT = __package__.rpartition(".")[0]
CORE_NAME = f"{_PARENT}.core" if _PARENT else "core"


def load(submodule=None):
    """Import and return the core package, or one of its submodules (``load("imageio")``)."""
    return importlib.import_module(CORE_NAME if submodule is None else f"{CORE_NAME}.{submodule}")


def missing_dependency():
    """A message naming what the core needs and this Python lacks, or None when all is there.

    The core imports embreex only when a bake starts; this finds its absence before any work.
    The extension zip bundles embreex as a wheel; a checkout needs it installed (pip install embreex).
    """
    missing = [name for name in ("numpy", "embreex") if importlib.util.find_spec(name) is None]
    if not missing:
        return None
    return (
        f"the Python module{'s' if len(missing) > 1 else ''} {' and '.join(missing)} "
        f"{'are' if len(missing) > 1 else 'is'} missing: install the mc_ao extension zip, which "
        "bundles embreex, or pip install it into this Python"
    )
