"""A thickness map at its defaults works: with no distance given (unlimited), its rays look a twentieth
of the target's size into the mesh (core.engine.thickness.SIZE_FRACTION), not forever (every inward
ray of a closed mesh would meet the far side: black), and the result says which distance it used."""

from pathlib import Path

import numpy as np
import pytest

from core import Mesh, bake_ao, bake_maps
from core.engine import thickness

SCENE = Path(__file__).resolve().parents[1] / "bench" / "data" / "scene_suzanne.npz"


@pytest.fixture(scope="module")
def suzanne():
    z = np.load(SCENE)
    return Mesh(z["P"], z["F"], uvs=z["UV"], normals=z["N"], name="Suzanne")


def diagonal(mesh):
    return float(np.linalg.norm(mesh.positions.max(axis=0) - mesh.positions.min(axis=0)))


def test_thickness_at_its_defaults_on_suzanne_is_a_map_not_black(suzanne):
    r = bake_ao(suzanne, [], resolution=128, samples=64, quantity="thickness", seed=2)
    t = r.ao[r.mask]
    assert 0.2 < t.mean() < 0.9, t.mean()
    assert np.mean(t < 0.02) < 0.05, np.mean(t < 0.02)
    assert r.metadata["max_distance"] == pytest.approx(diagonal(suzanne) / 20)  # which distance: in the result


def test_unlimited_really_was_black(suzanne):
    """Why the default: rays that look forever meet Suzanne's far side from everywhere."""
    r = bake_ao(suzanne, [], resolution=64, samples=32, quantity="thickness", thickness_distance=1e9, seed=2)
    assert r.ao[r.mask].mean() < 0.1


def test_a_given_distance_is_the_one_used(suzanne):
    by_max = bake_ao(suzanne, [], resolution=32, samples=8, quantity="thickness", max_distance=0.3)
    assert by_max.metadata["max_distance"] == 0.3
    own = bake_maps(suzanne, [], resolution=32, samples=8, max_distance=0.7, thickness_distance=0.2)
    assert own["thickness"].metadata["max_distance"] == 0.2 and own["ao"].metadata["max_distance"] == 0.7


def test_ao_beside_it_keeps_its_unlimited_distance_and_each_map_its_bits(suzanne):
    maps = bake_maps(suzanne, [], resolution=32, samples=8, seed=5)
    assert maps["ao"].metadata["max_distance"] == float("inf")
    assert maps["thickness"].metadata["max_distance"] == pytest.approx(diagonal(suzanne) / 20)
    alone = bake_ao(suzanne, [], resolution=32, samples=8, seed=5, quantity="thickness")
    np.testing.assert_array_equal(maps["thickness"].ao, alone.ao)


def test_an_atlas_takes_its_largest_targets_size():
    small = Mesh(np.array([[0, 0, 0], [1, 0, 0], [0, 1, 0]], float), np.array([[0, 1, 2]]), name="small")
    big = Mesh(small.positions * 4, small.triangles, name="big")
    assert thickness.default_distance([small, big]) == pytest.approx(diagonal(big) / 20)
