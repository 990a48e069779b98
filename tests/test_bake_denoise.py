"""bake_ao(..., denoise=True): the denoised map and its error in ``ao`` and ``stderr``, the raw estimate
kept, the same for any workers and threads, and refused where the error it needs is not honest."""

import numpy as np
import pytest

from core import Mesh, SettingsError, bake_ao, bake_udim
from core.post import denoise as D
from scenes import QUAD, plane

LID = np.array([[0.25, 0.25, 0.3], [0.75, 0.25, 0.3], [0.75, 0.75, 0.3], [0.25, 0.75, 0.3]])


def lid():
    return Mesh(LID, QUAD, name="lid")


def test_the_bake_returns_the_denoised_map_and_keeps_the_raw_one():
    args = dict(resolution=32, samples=16, seed=4, margin=0, threads=1)
    raw = bake_ao(plane(), [lid()], **args)
    r = bake_ao(plane(), [lid()], denoise=True, **args)
    assert np.array_equal(r.raw_ao, raw.ao) and np.array_equal(r.raw_stderr, raw.stderr)
    want_ao, want_se, _ = D.denoise(raw.ao, raw.stderr, raw.mask, D.surface_guide(plane(), (32, 32)), threads=1)
    assert np.array_equal(r.ao, want_ao) and np.array_equal(r.stderr, want_se)
    assert not np.array_equal(r.ao, raw.ao) and r.metadata["denoise"] is True
    assert raw.raw_ao is None and "denoise" not in raw.metadata


def test_denoised_bakes_are_the_same_for_any_threads_and_workers():
    args = dict(resolution=32, samples=16, seed=4, margin=4, denoise=True)
    a = bake_ao(plane(), [lid()], threads=1, **args)
    for kw in (dict(threads=2), dict(workers=2)):
        b = bake_ao(plane(), [lid()], **kw, **args)
        for name in ("ao", "stderr", "raw_ao", "raw_stderr"):
            assert np.array_equal(getattr(a, name), getattr(b, name)), (kw, name)


def test_udim_tiles_are_denoised_each():
    p = plane()
    tiled = Mesh(p.positions, p.triangles, p.uvs + [1.0, 0.0], name="tile1002")
    r = bake_udim(tiled, [lid()], resolution=16, samples=16, denoise=True, threads=1)
    assert r.raw_ao.shape == r.ao.shape == (1, 16, 16) and not np.array_equal(r.raw_ao, r.ao)


def test_one_replicate_is_refused_with_denoise():
    with pytest.raises(SettingsError, match="denoise needs replicates"):
        bake_ao(plane(), resolution=8, samples=8, replicates=1, denoise=True)


def test_vertex_bakes_are_denoised_over_the_mesh_and_keep_the_raw_values():
    from core import bake_vertex_ao

    n = 8
    x, y = np.meshgrid(np.linspace(0, 1, n + 1), np.linspace(0, 1, n + 1))
    P = np.stack([x, y, np.zeros_like(x)], -1).reshape(-1, 3)
    i = np.arange(n)[:, None] * (n + 1) + np.arange(n)[None, :]
    F = np.concatenate([np.stack([i, i + 1, i + n + 2], -1).reshape(-1, 3),
                        np.stack([i, i + n + 2, i + n + 1], -1).reshape(-1, 3)])
    grid = Mesh(P, F, name="grid")
    raw = bake_vertex_ao(grid, [lid()], samples=16, seed=2, threads=1)
    r = bake_vertex_ao(grid, [lid()], samples=16, seed=2, threads=1, denoise=True)
    assert np.array_equal(r.raw_ao, raw.ao) and np.array_equal(r.raw_stderr, raw.stderr)
    want, want_se, _ = D.denoise_vertices(grid, raw.ao, raw.stderr, raw.unit)
    assert np.allclose(r.ao, want) and not np.array_equal(r.ao, raw.ao)


def _fine_mesh():
    """A bumpy 24 x 24 grid (smooth normals) in two UV islands: the left half as is, the right half
    turned and scaled down so that its triangles are smaller than a texel at 32^2, overlapping the
    left half's corner (texels inside one triangle, located among several, split by island borders
    and by overlapping islands)."""
    n = 24
    x, y = np.meshgrid(np.linspace(0, 1, n + 1), np.linspace(0, 1, n + 1))
    z = 0.1 * np.sin(5 * x) * np.cos(4 * y)
    P = np.stack([x, y, z], -1).reshape(-1, 3)
    i = np.arange(n)[:, None] * (n + 1) + np.arange(n)[None, :]
    F = np.concatenate([np.stack([i, i + 1, i + n + 2], -1).reshape(-1, 3),
                        np.stack([i, i + n + 2, i + n + 1], -1).reshape(-1, 3)])
    UV = P[F][:, :, :2] * 0.55
    right = P[F][:, :, 0].mean(axis=1) > 0.5
    UV[right] = 0.4 + 0.3 * (P[F][right][:, :, [1, 0]] - 0.5)
    N = np.stack([-0.5 * np.cos(5 * x) * np.cos(4 * y), 0.4 * np.sin(5 * x) * np.sin(4 * y), np.ones_like(x)], -1)
    N = (N / np.linalg.norm(N, axis=-1, keepdims=True)).reshape(-1, 3)[F]
    return Mesh(P, F, UV, N, name="fine")


def _suzanne():
    from pathlib import Path

    z = np.load(Path(__file__).resolve().parents[1] / "bench" / "data" / "scene_suzanne.npz")
    return Mesh(z["P"], z["F"], z["UV"], z["N"], name="Suzanne")


@pytest.mark.parametrize("target, res", [("fine", 32), ("fine", 45), ("suzanne", 96), ("suzanne", 157)])
def test_the_guide_the_bake_builds_from_its_tiles_is_the_one_computed_from_the_mesh(monkeypatch, target, res):
    mesh = _fine_mesh() if target == "fine" else _suzanne()
    seen = []
    compute = D.surface_guide

    def record(m, resolution, radius=D.RADIUS, texels=None, threads=1, tris=None):
        seen.append((m, texels))
        out = compute(m, resolution, radius, texels=texels, tris=tris)
        # Nothing whole-mesh of the UV triangles was kept for the guide: its tiles asked for their
        # own triangles' corners and edge functions.
        assert "edges" not in vars(tris) and "xy" not in vars(tris)
        return out

    monkeypatch.setattr(D, "surface_guide", record)
    r = bake_ao(mesh, resolution=res, samples=2, seed=1, threads=2, tile_size=16, denoise=True)
    (baked, texels), = seen
    assert texels is not None  # the bake passed what its tiles found
    assert np.array_equal(texels[0].reshape(res, res) >= 0, r.mask)
    from_tiles = compute(baked, res, texels=texels)
    from_mesh = compute(baked, res)
    for field in ("covered", "triangle", "position", "normal", "scale", "island", "halo_island", "halo_row",
                  "halo_col", "halo_source", "links"):
        assert np.array_equal(getattr(from_tiles, field), getattr(from_mesh, field)), field
