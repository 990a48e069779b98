"""float32 tables: the types of the hot arrays, and the precision a scene far from the origin keeps.

The surface table and the UV triangles keep float32 (Blender's and Embree's geometry is float32),
each value computed in float64 and rounded once; every ray's arithmetic is float32 and every sum
over samples and texels float64. A scene 1e4 units from the origin, given in float32 as Blender
gives it, bakes the AO it bakes at the origin, within the error of its own estimate."""

import math

import numpy as np
import pytest

import core.engine.kernel as kernel_mod
from core import Mesh, bake_ao
from core.engine.estimators import TexelEstimates
from core.geometry.raster import prepare
from core.montecarlo.stats import normal_quantile
from core.geometry.surface import SurfaceTable
from scenes import plane, polygon_form_factor, texel_mean

LID = np.array([[0.25, 0.25, 0.3], [0.75, 0.25, 0.3], [0.75, 0.75, 0.3], [0.25, 0.75, 0.3]])
QUAD = np.array([[0, 1, 2], [0, 2, 3]])


def smooth_plane():
    """The unit plane with corner normals tilted (a smooth-shaded triangle: the curved kernel form)."""
    m = plane()
    N = np.tile([0.1, 0.0, 1.0], (2, 3, 1))
    return Mesh(m.positions, m.triangles, m.uvs, N, name="smooth")


def test_the_hot_arrays_have_their_types(monkeypatch):
    mesh = smooth_plane()
    uvtris = prepare(mesh, 16, 16)
    assert uvtris.corners32.dtype == np.float32
    assert uvtris.corners.dtype == np.float64 and uvtris.corners_of(np.array([1])).dtype == np.float64
    table = SurfaceTable.build(mesh, uvtris)
    for field in ("origin", "P0", "Px", "Py", "N0", "Nx", "Ny", "FN", "corners_xy"):
        assert getattr(table, field).dtype == np.float32, field
        assert table.take(field, np.array([0, 1])).dtype == np.float64, field
    # What one bake's tiles and kernel hold, and what its rays are.
    contexts, estimates, batches = [], [], []
    context_init, add = kernel_mod.TileContext.__init__, TexelEstimates.add

    def spy_context(self, *a, **kw):
        context_init(self, *a, **kw)
        contexts.append(self)

    def spy_add(self, *a, **kw):
        estimates.append(self)
        return add(self, *a, **kw)

    monkeypatch.setattr(kernel_mod.TileContext, "__init__", spy_context)
    monkeypatch.setattr(TexelEstimates, "add", spy_add)
    lid = Mesh(LID, QUAD, name="lid")
    for target in (mesh, plane()):
        r = bake_ao(target, [lid], resolution=16, samples=16, margin=0, on_rays=batches.append)
        assert r.ao.dtype == np.float32 and r.stderr.dtype == np.float32
    assert contexts and estimates and batches
    for c in contexts:
        assert c.flat_m.dtype == c.curved_m.dtype == c.coef_planes.dtype == np.float32
        assert c.flat_rows.dtype == c.curved_rows.dtype == np.float32
    assert any(len(c.curved_m) for c in contexts) and any(len(c.flat_m) for c in contexts)
    for b in batches:
        assert b.origins.dtype == b.directions.dtype == b.tfar.dtype == np.float32
    for e in estimates:  # the sums over samples
        for name, value in vars(e).items():
            if isinstance(value, np.ndarray) and value.dtype.kind == "f":
                assert value.dtype == np.float64, name


def _lid_scene(offset, dtype):
    """The plane under the lid, moved by ``offset``, its positions in ``dtype``."""
    P = (plane().positions + offset).astype(dtype)
    target = Mesh(P, QUAD, plane().uvs, name="plane")
    return target, [Mesh((LID + offset).astype(dtype), QUAD, name="lid")]


@pytest.mark.parametrize("seed", [0, 1, 2])
def test_a_scene_far_from_the_origin_bakes_what_it_bakes_at_the_origin(seed):
    """The plane under a lid 1e4 units away in every axis, in float32 as Blender gives it: its AO
    against Lambert's exact answer as the bake at the origin is (no bias, an honest error), and its
    texels within the float32 input's own precision of the origin's."""
    W = H = 24
    truth = texel_mean(lambda p: 1.0 - polygon_form_factor(p, LID), W, H)
    far = np.array([1e4, -1e4, 1e4])
    kw = dict(resolution=(W, H), samples=256, source="independent", margin=0, seed=seed)
    near = bake_ao(*_lid_scene(0.0, np.float64), **kw)
    moved = bake_ao(*_lid_scene(far, np.float32), **kw)
    m = W * H
    # The sample variance of m unit-variance z has a standard deviation of sqrt(2 / (m - 1)): 4 of them.
    spread = 4 * math.sqrt(2 / (m - 1))
    for r in (near, moved):
        z = (r.ao - truth) / r.stderr
        assert abs(z.mean()) < 4 / math.sqrt(m), z.mean()
        assert 1 - spread < z.var() < 1 + spread, z.var()
        assert np.abs(z).max() < normal_quantile(1 - 0.01 / (2 * m)) + 0.5
    # float32 positions 1e4 away are rounded by up to 2^-11 (half a unit in the last place of 1e4):
    # the lid's height moves by that at most, 0.2% of its 0.3, and AO with it by about as much.
    assert np.abs(moved.ao.astype(np.float64) - near.ao).mean() < 2e-3
    # In float64 the same scene far away is the same scene: the bake normalises it to its own frame.
    same = bake_ao(*_lid_scene(far, np.float64), **kw)
    assert np.abs(same.ao.astype(np.float64) - near.ao).max() < 1e-6
