"""Selected to active without the extrusion trap: the automatic extrusion (core.highpoly.extrusion.auto_extrusion)
against hand-set ones on a bumpy high-poly over a coarse low-poly and in a narrow slot whose far wall
is also 'outside', and the warning when matching rays meet the high-poly from behind. (The same on
sample_scenes/rock.blend: tests/blender/test_auto_extrusion_rock.py.)"""

import numpy as np
import pytest

from core import Mesh, SettingsError, bake_ao
from core.highpoly.extrusion import auto_extrusion
from scenes import QUAD, plane

A = 0.05    # how far the high-poly bulges out of (and sinks into) the low-poly
GAP = 0.3   # the slot's width
LID = np.array([[0.25, 0.25, 0.3], [0.75, 0.25, 0.3], [0.75, 0.75, 0.3], [0.25, 0.75, 0.3]])


def grid(f, n=48, lo=-0.2, hi=1.2, name="high"):
    """A grid over [lo, hi]^2 of (u, v) mapped to 3D points by f(u, v) -> (x, y, z) arrays."""
    t = np.linspace(lo, hi, n + 1)
    U, V = np.meshgrid(t, t)
    P = np.stack(f(U.ravel(), V.ravel()), axis=1)
    i = np.arange(n)
    a = (i[None, :] + (n + 1) * i[:, None]).ravel()
    F = np.concatenate([np.stack([a, a + 1, a + n + 2], 1), np.stack([a, a + n + 2, a + n + 1], 1)])
    return Mesh(P, F, name=name)


def bumps(u, v):
    return np.sin(9.0 * u + 0.3) * np.cos(7.0 * v)  # in [-1, 1]


def bumpy_plane():
    """A coarse low plane (2 triangles) and the top of a high-poly slab bulging A above and below it,
    under a lid. The slab's bottom (facing down, 0.3 below) is what a matching ray that starts inside
    the slab meets first, from behind: the blobs of a too small extrusion."""
    top = grid(lambda u, v: (u, v, A * bumps(u, v)))
    bottom = grid(lambda u, v: (v, u, np.full_like(u, -0.3)))  # faces -z
    lid = Mesh(LID, QUAD, name="lid")
    high = Mesh(np.concatenate([top.positions, bottom.positions]),
                np.concatenate([top.triangles, bottom.triangles + len(top.positions)]), name="high")
    return plane(name="low"), [high], [lid]


def slot():
    """Two walls facing each other across a slot GAP wide (the low-poly, one UV half each), and
    their bumpy high-poly: where it sinks into a wall, the first surface out along that wall's normal
    is the far wall's, GAP away."""
    P = np.array([[0.0, 0.0, 0.0], [0.0, 1.0, 0.0], [0.0, 1.0, 1.0], [0.0, 0.0, 1.0],     # x = 0, facing +x
                  [GAP, 1.0, 0.0], [GAP, 0.0, 0.0], [GAP, 0.0, 1.0], [GAP, 1.0, 1.0]])  # x = GAP, facing -x
    F = np.array([[0, 1, 2], [0, 2, 3], [4, 5, 6], [4, 6, 7]])
    uv = np.array([[0, 0], [0.5, 0], [0.5, 1], [0, 1], [1, 0], [0.5, 0], [0.5, 1], [1, 1]], float)
    UV = uv[F]
    low = Mesh(P, F, UV, name="slot")
    near = grid(lambda u, v: (A * bumps(u, v), u, v), lo=0.0, hi=1.0, name="near wall")
    far = grid(lambda u, v: (GAP - A * bumps(v, u), v, u), lo=0.0, hi=1.0, name="far wall")  # faces -x
    return low, [near, far]


def agree(a, b):
    """Mean absolute difference over the texels both cover."""
    both = a.mask & b.mask
    return float(np.abs(a.ao - b.ao)[both].mean())


def test_the_automatic_extrusion_is_how_far_the_high_poly_bulges_out():
    low, highs, occ = bumpy_plane()
    kw = dict(resolution=32, samples=64, seed=2, margin=0)
    auto = bake_ao(low, occ, highpoly=highs, **kw)
    # The points it is measured from see nearly the whole bulge (A at the crests).
    assert 0.9 * A < auto.report["extrusion"] < 1.2 * A
    assert auto.metadata["extrusion_auto"] is True and auto.metadata["extrusion"] == auto.report["extrusion"]
    assert auto.report["warnings"] == [] and auto.report["missed_texels"] == 0
    # A hand-set extrusion that clears every bump matches every point to the same high-poly point:
    # with the same seed, the same AO rays (but for float rounding of the hit points).
    hand = bake_ao(low, occ, highpoly=highs, extrusion=0.2, **kw)
    assert hand.metadata["extrusion_auto"] is False and hand.report["warnings"] == []
    assert agree(auto, hand) < 0.005, agree(auto, hand)
    # Extrusion 0: the rays from under the bulges start inside the high-poly and bake its inside.
    zero = bake_ao(low, occ, highpoly=highs, extrusion=0.0, **kw)
    assert agree(zero, hand) > 10 * agree(auto, hand) and agree(zero, hand) > 0.05
    assert len(zero.report["warnings"]) == 1
    message = zero.report["warnings"][0]
    assert "'low'" in message and "'high'" in message and "from behind" in message and "extrusion" in message


def test_in_a_slot_the_far_wall_does_not_push_the_extrusion_out():
    low, highs = slot()
    kw = dict(resolution=32, samples=64, seed=3, margin=0)
    auto = bake_ao(low, highpoly=highs, **kw)
    e = auto.report["extrusion"]
    # Where the high-poly sinks into a wall, the first surface along that wall's normal is the far
    # wall, about GAP away: a quantile of those distances would take it; the bulges need A.
    assert 0.9 * A < e < 1.2 * A, e
    assert auto.report["warnings"] == []
    hand = bake_ao(low, highpoly=highs, extrusion=0.12, **kw)
    assert agree(auto, hand) < 0.005, agree(auto, hand)
    # Past the far wall the rays start behind it and match it: warned, and far off.
    far = bake_ao(low, highpoly=highs, extrusion=GAP + 0.1, **kw)
    assert len(far.report["warnings"]) == 1 and "'slot'" in far.report["warnings"][0]
    assert agree(far, hand) > 10 * agree(auto, hand)


def test_the_measure_serves_each_point_between_its_need_and_its_limit():
    low, highs = slot()
    from core.highpoly.scene import concatenate
    from core.tracing.tracer import embree_scene

    high = concatenate(highs, "high")
    m = auto_extrusion(low, embree_scene([high])[0], high.face_normals, count=1024)
    assert np.all(m.need >= 0) and np.all(m.need <= A * 1.001)
    inside = m.need == 0  # the points where the high-poly lies below the wall
    assert inside.any() and np.all(m.limit[inside] > GAP - A - 1e-6)  # their limit: the far wall
    assert m.served > 0.99 and m.need.max() <= m.extrusion < m.limit.min()


def test_an_explicit_auto_a_cage_and_bad_values():
    low, highs, occ = bumpy_plane()
    kw = dict(resolution=16, samples=16, seed=1, margin=0)
    assert np.array_equal(bake_ao(low, occ, highpoly=highs, extrusion="auto", **kw).ao,
                          bake_ao(low, occ, highpoly=highs, **kw).ao)
    cage = plane(z=0.2, name="cage")
    r = bake_ao(low, occ, highpoly=highs, cage=cage, **kw)
    assert r.report["extrusion"] == 0.0 and r.metadata["extrusion_auto"] is False
    with pytest.raises(SettingsError, match="the extrusion must be a number, got 'outside'"):
        bake_ao(low, occ, highpoly=highs, extrusion="outside", **kw)


def test_workers_bake_with_the_parents_measure():
    low, highs, occ = bumpy_plane()
    kw = dict(resolution=32, samples=16, seed=1, margin=2)
    one = bake_ao(low, occ, highpoly=highs, **kw)
    two = bake_ao(low, occ, highpoly=highs, workers=2, **kw)
    assert np.array_equal(one.ao, two.ao) and one.report["extrusion"] == two.report["extrusion"]


def test_workers_bake_a_measured_extrusion_in_an_odd_frame_with_the_same_bits():
    # Scaled by an odd factor: the frame's unit is not a power of two, and the workers, handed the
    # world extrusion, must arrive at the parent's value in the frame bit for bit.
    low, highs, occ = bumpy_plane()
    k = 1.37

    def scaled(m):
        return Mesh(m.positions * k, m.triangles, m.uvs, name=m.name)

    kw = dict(resolution=32, samples=16, seed=1, margin=0)
    one = bake_ao(scaled(low), [scaled(o) for o in occ], highpoly=[scaled(h) for h in highs], **kw)
    two = bake_ao(scaled(low), [scaled(o) for o in occ], highpoly=[scaled(h) for h in highs], workers=2, **kw)
    assert np.array_equal(one.ao, two.ao) and np.array_equal(one.stderr, two.stderr)
    assert one.report["extrusion"] == pytest.approx(k * bake_ao(low, occ, highpoly=highs, **kw).report["extrusion"])
