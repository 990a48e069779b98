"""The tests' process as a user's would be, whatever the clone's folder is named.

The repository root is a Python package (the extension's ``__init__.py``). Before its first test,
pytest imports that ``__init__.py`` and, in its default import mode, puts the root's parent folder
first on ``sys.path``: in a clone named ``mc_ao`` (the obvious name) every process started from the
tests (a Dask cluster's workers, which take this path) then finds the repository root as ``mc_ao``,
not the add-on's ``mc_ao/`` package. The session fixture below takes that entry off the path again,
and forgets the root package if it was imported under the name ``mc_ao``.
"""

import os
import sys

import pytest

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
_PARENT = os.path.dirname(ROOT)
_PARENT_ON_PATH = [p for p in sys.path if os.path.abspath(p or ".") == _PARENT]  # there before pytest's insertion


def restore_path():
    """Undo pytest's import of the repository root as a package (see the module docstring)."""
    extra = sum(os.path.abspath(p or ".") == _PARENT for p in sys.path) - len(_PARENT_ON_PATH)
    for _ in range(max(0, extra)):
        sys.path.remove(next(p for p in sys.path if os.path.abspath(p or ".") == _PARENT))
    root_package = sys.modules.get(os.path.basename(ROOT))
    if root_package is not None and os.path.abspath(getattr(root_package, "__file__", "") or "") == \
            os.path.join(ROOT, "__init__.py"):
        del sys.modules[os.path.basename(ROOT)]


@pytest.fixture(scope="session", autouse=True)
def _repository_root_is_not_a_package_on_the_path():
    restore_path()  # session fixtures run after pytest's set-up of the root package
    yield
