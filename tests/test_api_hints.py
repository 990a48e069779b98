"""The Python API's errors say what to pass: a single Mesh given as the occluders, UVs per vertex where
the Mesh takes them per triangle corner."""

import numpy as np
import pytest

from core import Mesh, SettingsError, MeshError, bake_ao, bake_udim, bake_vertex_ao

P = np.array([[-1, -1, 0], [1, -1, 0], [1, 1, 0], [-1, 1, 0]], float)
F = np.array([[0, 1, 2], [0, 2, 3]])
UV_PER_VERTEX = (P[:, :2] + 1) / 2


def ground():
    return Mesh(P, F, uvs=UV_PER_VERTEX[F], name="ground")


@pytest.mark.parametrize("bake", [
    lambda lid: bake_ao(ground(), lid, resolution=8, samples=4),
    lambda lid: bake_udim(ground(), lid, resolution=8, samples=4),
    lambda lid: bake_vertex_ao(ground(), lid, samples=4),
])
def test_a_single_mesh_as_occluders_says_to_pass_a_list(bake):
    lid = Mesh(P * [0.4, 0.4, 0] + [0, 0, 0.5], F, name="lid")
    with pytest.raises(SettingsError, match=r"got the single mesh 'lid': pass it in a list, occluders=\[mesh\]"):
        bake(lid)


def test_occluders_of_another_kind_are_named():
    with pytest.raises(SettingsError, match="occluders must be a list of core.Mesh objects, got int"):
        bake_ao(ground(), 3, resolution=8, samples=4)
    with pytest.raises(SettingsError, match="occluders must be core.Mesh objects, got ndarray"):
        bake_ao(ground(), [P], resolution=8, samples=4)


def test_uvs_per_vertex_say_to_index_them_by_the_triangles():
    with pytest.raises(MeshError, match=r"one UV per vertex, shape \(4, 2\).*shape \(2, 3, 2\): pass uvs\[triangles\]"):
        Mesh(P, F, uvs=UV_PER_VERTEX, name="ground")
    assert ground().uvs.shape == (2, 3, 2)  # what the hint says to pass works


def test_the_hinted_fix_bakes():
    lid = Mesh(P * [0.4, 0.4, 0] + [0, 0, 0.5], F, name="lid")
    assert bake_ao(ground(), [lid], resolution=8, samples=4).mask.any()
