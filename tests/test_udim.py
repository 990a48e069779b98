"""UDIM tiles in the core: which tiles a layout touches, each baked as its own image with
the UVs shifted by the tile's origin, against Lambert's exact AO; tiles far apart; UVs on borders."""

import math

import numpy as np
import pytest

from core import Mesh, SettingsError, bake_ao
from core import bake_udim
from core.geometry.uvtiles import covered_tiles, tile_origin
from core.montecarlo.stats import normal_quantile
from scenes import polygon_form_factor, texel_mean

QUAD = np.array([[0, 1, 2], [0, 2, 3]])
# A square lid at height 0.3 over the right half (x in [1, 2]) of a 2 x 1 plane.
LID = np.array([[1.25, 0.25, 0.3], [1.75, 0.25, 0.3], [1.75, 0.75, 0.3], [1.25, 0.75, 0.3]])


def lid():
    return Mesh(LID, QUAD, name="lid")


def quad(x0, y0, x1, y1, uv0, uv1, z=0.0):
    """Corners (4, 3), UVs (4, 2) of a rectangle mapped onto the UV rectangle uv0 .. uv1."""
    P = np.array([[x0, y0, z], [x1, y0, z], [x1, y1, z], [x0, y1, z]], float)
    (u0, v0), (u1, v1) = uv0, uv1
    UV = np.array([[u0, v0], [u1, v0], [u1, v1], [u0, v1]], float)
    return P, UV


def mesh_of(*quads, name="plane"):
    P = np.concatenate([q[0] for q in quads])
    UV = np.concatenate([q[1] for q in quads])
    F = np.concatenate([QUAD + 4 * i for i in range(len(quads))])
    return Mesh(P, F, uvs=UV[F], name=name)


def check_against_truth(r, truth, samples):
    """A tile's texels against their exact AO, for independent cosine samples (each texel's estimate
    is a binomial proportion: variance truth (1 - truth) / samples): unbiased overall, none far off."""
    var = truth * (1.0 - truth) / samples
    total = (r.ao - truth).sum() / math.sqrt(var.sum())
    assert abs(total) < 4, total
    z = (r.ao - truth) / np.sqrt(var)
    assert np.abs(z).max() < normal_quantile(1 - 0.01 / (2 * z.size)) + 1.0, np.abs(z).max()


def test_a_plane_over_tiles_1001_and_1002_with_an_occluder_over_one_half():
    """The plane x in [0, 2] has UVs (x, y): tile 1001 is its left half, 1002 its right half, under the
    lid. Each tile is a full image of the bake's size whose texels hold the exact AO of their part of
    the plane (the lid darkens 1002 and, a little, the edge of 1001 next to it)."""
    plane = mesh_of(quad(0, 0, 2, 1, (0, 0), (2, 1)))
    W = H = 16
    r = bake_udim(plane, [lid()], resolution=(W, H), samples=256, source="independent", margin=0, seed=5)
    assert sorted(r.tiles) == [1001, 1002] and r.report["tiles"] == [1001, 1002]
    for tile, x0 in ((1001, 0.0), (1002, 1.0)):
        res = r.tiles[tile]
        assert res.ao.shape == (H, W) and res.mask.all()
        truth = texel_mean(lambda p: 1.0 - polygon_form_factor(p, LID), W, H, bounds=(x0, 0.0, x0 + 1, 1.0))
        check_against_truth(res, truth, 256)
    assert r.tiles[1002].ao.mean() < 0.85 < 0.95 < r.tiles[1001].ao.mean()
    assert r.report["uv_outside_udim_triangles"] == 0 and r.report["covered_texels"] == 2 * W * H


def test_tiles_far_apart_are_the_only_ones_baked():
    """Two islands in tiles 1001 and 1013 (u in [2, 3], v in [1, 2]): two tiles, nothing between."""
    plane = mesh_of(quad(0, 0, 1, 1, (0, 0), (1, 1)), quad(1, 0, 2, 1, (2, 1), (3, 2)))
    assert covered_tiles(plane).tiles == [1001, 1013]
    assert tile_origin(1013) == (2, 1)
    W = H = 12
    # The tiles' own estimates: the quads share an edge in space, a seam Fix Seams would work on.
    r = bake_udim(plane, [lid()], resolution=(W, H), samples=256, source="independent", margin=0, seed=1,
                  fix_seams=False)
    assert sorted(r.tiles) == [1001, 1013]
    truth = texel_mean(lambda p: 1.0 - polygon_form_factor(p, LID), W, H, bounds=(1.0, 0.0, 2.0, 1.0))
    check_against_truth(r.tiles[1013], truth, 256)
    assert np.all(r.tiles[1001].mask)


def test_uvs_on_tile_borders_are_exact():
    """An edge on u = 1 does not touch 1002; a square exactly on [1, 2] x [0, 1] is 1002 alone, every
    texel of it covered whole; an island across the border is split between the tiles texel-exactly."""
    left = quad(0, 0, 1, 1, (0, 0), (1, 1))
    right = quad(1, 0, 2, 1, (1, 0), (2, 1))
    assert covered_tiles(mesh_of(left)).tiles == [1001]
    assert covered_tiles(mesh_of(right)).tiles == [1002]
    corner = quad(0, 0, 1, 1, (1, 1), (2, 2))  # touches 1001, 1002 and 1011 at the corner (1, 1) only
    assert covered_tiles(mesh_of(corner)).tiles == [1012]
    W = H = 8
    r = bake_udim(mesh_of(right), resolution=(W, H), samples=16, margin=0)
    assert list(r.tiles) == [1002] and r.tiles[1002].mask.all() and np.all(r.tiles[1002].ao == 1.0)
    # Across the border: UVs u in [0.5, 1.5]: the right half columns of 1001, the left half of 1002.
    across = mesh_of(quad(0, 0, 1, 1, (0.5, 0), (1.5, 1)))
    r = bake_udim(across, resolution=(W, H), samples=16, margin=0)
    assert sorted(r.tiles) == [1001, 1002]
    left_half = np.zeros((H, W), bool)
    left_half[:, : W // 2] = True
    np.testing.assert_array_equal(r.tiles[1001].mask, ~left_half)
    np.testing.assert_array_equal(r.tiles[1002].mask, left_half)
    # A border in the middle of a texel: u in [0.55, 1.55] at 8 texels: the texel column holding u = 1
    # is covered in both tiles (each by its own part of the island).
    r = bake_udim(mesh_of(quad(0, 0, 1, 1, (0.55, 0), (1.55, 1))), resolution=(W, H), samples=16, margin=0)
    cols_1001 = np.flatnonzero(r.tiles[1001].mask[0])
    cols_1002 = np.flatnonzero(r.tiles[1002].mask[0])
    assert cols_1001.tolist() == [4, 5, 6, 7] and cols_1002.tolist() == [0, 1, 2, 3, 4]


@pytest.mark.parametrize("past", [1e-7, 1e-12, 1e-14])
def test_a_tile_is_listed_exactly_when_its_bake_covers_a_texel(past):
    """UVs a rounding error past a border (u = 1 + past): the next tile is in the list at a size
    exactly when the rasteriser covers one of its texels there (the same threshold), never empty."""
    sliver = mesh_of(quad(0, 0, 1, 1, (0, 0), (1 + past, 1)))
    assert covered_tiles(sliver).tiles == [1001, 1002]  # any positive area
    for size in (8, 64, 512):
        listed = covered_tiles(sliver, resolution=size).tiles
        r = bake_udim(sliver, resolution=size, samples=1, margin=0, tiles=[1001, 1002])
        assert listed == [t for t in (1001, 1002) if r.tiles[t].mask.any()], (size, listed)


def test_tile_1001_is_the_plain_bake_and_other_tiles_draw_their_own_noise():
    """A layout inside [0, 1] bakes bit for bit as without UDIM; the same island in 1002 draws other
    random numbers (tiles do not repeat each other's noise)."""
    kw = dict(resolution=16, samples=32, margin=2, seed=7, fix_seams=False)  # the two quads coincide in space
    plain = bake_ao(mesh_of(quad(0, 0, 1, 1, (0, 0), (1, 1))), [lid()], **kw)
    r = bake_udim(mesh_of(quad(0, 0, 1, 1, (0, 0), (1, 1)), quad(0, 0, 1, 1, (1, 0), (2, 1))), [lid()], **kw)
    np.testing.assert_array_equal(r.tiles[1001].ao, plain.ao)
    np.testing.assert_array_equal(r.tiles[1001].stderr, plain.stderr)
    assert not np.array_equal(r.tiles[1002].ao, r.tiles[1001].ao)


def test_margin_is_per_tile():
    """Each tile's islands grow into that tile's own margin; the tile across the border is not read."""
    W = H = 16
    r = bake_udim(mesh_of(quad(0, 0, 1, 1, (0.25, 0.25), (1.5, 0.75))), resolution=(W, H), samples=16, margin=3)
    for tile in (1001, 1002):
        res = r.tiles[tile]
        filled = res.ao > 0
        assert np.all(filled[res.mask]) and (filled & ~res.mask).any()
        rows = np.flatnonzero(res.mask.any(axis=1))
        assert filled[rows.min() - 3: rows.max() + 4].any(axis=1).all()
        assert not filled[: rows.min() - 3].any() and not filled[rows.max() + 4:].any()


def test_triangles_outside_the_tiles_are_counted_and_listed_tiles_are_checked():
    mesh = mesh_of(quad(0, 0, 1, 1, (-0.5, 0.25), (0.5, 0.75)), quad(1, 0, 2, 1, (1, 0), (2, 1)))
    cov = covered_tiles(mesh)
    assert cov.tiles == [1001, 1002] and cov.outside == 2
    r = bake_udim(mesh, resolution=8, samples=8, margin=0)
    assert r.report["uv_outside_udim_triangles"] == 2 and "uv_outside_triangles" not in r.report
    # A listed tile the UVs miss is baked empty (as Cycles clears it).
    r = bake_udim(mesh, resolution=8, samples=8, margin=0, tiles=[1002, 1005])
    assert sorted(r.tiles) == [1002, 1005] and not r.tiles[1005].mask.any()
    with pytest.raises(SettingsError, match="2001"):
        bake_udim(mesh, resolution=8, samples=8, tiles=[2001])


def test_progress_covers_every_tile_and_ends_at_one():
    seen = []
    mesh = mesh_of(quad(0, 0, 1, 1, (0, 0), (1, 1)), quad(1, 0, 2, 1, (2, 1), (3, 2)))
    bake_udim(mesh, resolution=16, samples=16, progress=seen.append, threads=1)
    assert seen == sorted(seen) and seen[-1] == 1.0 and any(0.4 < f < 0.6 for f in seen)
