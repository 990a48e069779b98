"""The same bits on numpy 1.26 and 2.x: the fingerprints scripts/output_hashes.py keeps for each numpy
line are equal (made with .venv and .venv-numpy2), and this tree bakes its own line's fingerprints
for the cases that once differed (the smooth-shaded Suzanne's rays and bent normals). The suite runs
on both lines (.ci/run), so each line checks itself against its list, and the lists against each other."""

import importlib.util
import sys
from pathlib import Path

import numpy as np
import pytest

ROOT = Path(__file__).resolve().parent.parent
LISTS = ROOT / "scripts" / "output_hashes"


def _lines(path):
    return [line for line in path.read_text().splitlines() if not line.startswith("#")]


def test_both_numpy_lines_keep_the_same_fingerprints():
    one, two = _lines(LISTS / "numpy1.txt"), _lines(LISTS / "numpy2.txt")
    # .venv-numpy2 has no distributed: its Dask cases are skipped, every other case is in both lists.
    one = [line for line in one if not line.startswith("dask/")]
    two = [line for line in two if not line.startswith("dask/")]
    assert len(one) == len(two) > 500
    different = [(a, b) for a, b in zip(one, two) if a != b]
    assert different == []


@pytest.mark.parametrize("pattern", ["image/suzanne/bent-world", "corners/suzanne/no-merge-bent"])
def test_this_tree_bakes_its_numpy_lines_fingerprints(pattern):
    spec = importlib.util.spec_from_file_location("output_hashes", ROOT / "scripts" / "output_hashes.py")
    hashes = importlib.util.module_from_spec(spec)
    sys.modules.setdefault("output_hashes", hashes)
    spec.loader.exec_module(hashes)
    lines = hashes.run(pattern)
    want = [line for line in _lines(LISTS / f"numpy{np.__version__.split('.')[0]}.txt")
            if line.split(" ", 1)[0].split(":")[0] == pattern]
    assert lines and lines == want
