"""Fix Seams: the seam lookups against Blender's Linear interpolation written out, the least-squares
fix against the dense solution of its own objective, what it must leave alone, and its error map on
exact scenes (tests/seam_scenes.py). Sizes 64^2 and below; nothing timed."""

import numpy as np
import pytest

from core.geometry import seams as G
from core.post import fixseams as F
from core import Mesh, bake_ao
from seam_scenes import bilinear_lookup, charts

W = 64


def split_plane():
    """The unit plane cut along x = 0.5 into two UV islands: the left half as it is in u in
    [0, 0.5], the right half turned by 180 degrees into u in [0.5, 1]. The seam runs along u = 0.5
    on the left island and along u = 1, the image's border, on the right."""
    P = np.array([[0, 0, 0], [.5, 0, 0], [1, 0, 0], [0, 1, 0], [.5, 1, 0], [1, 1, 0]], float)
    F = np.array([[0, 1, 4], [0, 4, 3], [1, 2, 5], [1, 5, 4]])
    UV = P[F][:, :, :2].copy()
    UV[2:] = np.stack([1.5 - UV[2:, :, 0], 1.0 - UV[2:, :, 1]], -1)
    return Mesh(P, F, UV, name="split")


def point_position(mesh, tri, uv):
    """The surface point at ``uv`` of triangle ``tri`` (barycentrics from its UV triangle)."""
    a, b, c = mesh.uvs[tri]
    m = np.array([b - a, c - a]).T
    l1, l2 = np.linalg.solve(m, uv - a)
    p = mesh.positions[mesh.triangles[tri]]
    return (1 - l1 - l2) * p[0] + l1 * p[1] + l2 * p[2]


# --- the lookups ----------------------------------------------------------------------------------

def test_every_chart_edge_inside_the_plane_is_a_seam_sampled_four_times_a_texel():
    target, _, _, _ = charts(grid=2, cell=28)
    L = G.seam_lookups(target, W)
    assert L.edges == 4 and L.points == 4 * 28 * G.POINTS_PER_TEXEL
    assert np.allclose(L.length, 0.25)
    # Each side's weights are a partition of unity; side B's are negated.
    assert np.allclose(L.weight[:, :4].sum(1), 1) and np.allclose(L.weight[:, 4:].sum(1), -1)


@pytest.mark.parametrize("wrap", ["repeat", "extend"])
def test_the_two_lookups_of_a_point_are_one_surface_point_read_as_blender_reads_it(wrap):
    target, _, _, _ = charts(grid=3, cell=18, gap=3)
    L = G.seam_lookups(target, W, wrap=wrap)
    image = np.random.default_rng(1).random((W, W)).astype(np.float32)
    diff = L.difference(image)
    for k in np.linspace(0, L.points - 1, 60).astype(int):
        (ua, va), (ub, vb) = L.uv[k]
        ta, tb = L.triangle[k]
        np.testing.assert_allclose(point_position(target, ta, L.uv[k, 0]), point_position(target, tb, L.uv[k, 1]),
                                   atol=1e-9)
        slow = bilinear_lookup(image, ua, va, wrap) - bilinear_lookup(image, ub, vb, wrap)
        assert diff[k] == pytest.approx(slow, abs=1e-6)


def test_a_seam_on_the_image_border_reads_the_opposite_border_when_the_image_repeats():
    L = {w: G.seam_lookups(split_plane(), 8, wrap=w) for w in ("repeat", "extend")}
    assert L["repeat"].edges == 1
    # Side B lies on u = 1: its lookups read column 7 and, wrapped, column 0 (extend: 7 twice).
    cols = {w: np.unique(l.index[:, 4:][l.weight[:, 4:] != 0] % 8) for w, l in L.items()}
    assert set(cols["repeat"]) == {0, 7} and set(cols["extend"]) == {7}


def test_a_constant_map_has_no_mismatch_and_a_map_of_the_surface_none_inside_an_island():
    target, _, _, _ = charts()
    L = G.seam_lookups(target, W)
    assert L.mismatch(np.full((W, W), 0.37, np.float32)) == pytest.approx(0, abs=1e-7)
    assert G.seam_mismatch(target, np.zeros((W, W))) == 0


def folded_plane(smooth):
    """split_plane with its right half folded up by 90 degrees about the seam (x = 0.5): a crease,
    unless ``smooth`` gives both halves the same corner normals (the fold's bisector) along it."""
    m = split_plane()
    P = m.positions.copy()
    P[[2, 5]] = [[0.5, 0, 0.5], [0.5, 1, 0.5]]
    N = None
    if smooth:
        fold = np.array([-1.0, 0.0, 1.0]) / np.sqrt(2)
        N = np.where(np.isin(m.triangles, [1, 4])[..., None], fold, 0.0)
        N[:2] = np.where(N[:2].any(-1, keepdims=True), N[:2], [0, 0, 1.0])
        N[2:] = np.where(N[2:].any(-1, keepdims=True), N[2:], [-1.0, 0, 0])
    return Mesh(P, m.triangles, m.uvs, N, name="folded")


@pytest.mark.parametrize("smooth", [False, True])
def test_a_seam_on_a_crease_is_measured_but_left_alone(smooth):
    # A 90-degree fold along the seam: with each face's own normal the AO may differ across it (the
    # seam is what lets the map show that), so the fix takes no part there; with one shading normal
    # on both sides (smooth shading) it makes them agree.
    m = folded_plane(smooth)
    L = G.seam_lookups(m, 16)
    assert L.edges == 1 and L.points == 64 and L.crease.all() != smooth
    image = np.random.default_rng(4).random((16, 16)).astype(np.float32)
    stderr = np.full((16, 16), 0.01, np.float32)
    out, se, info = F.fix_seams(image, stderr, np.ones((16, 16), bool), L)
    if smooth:
        assert info.after < 0.1 * info.before == pytest.approx(0.1 * L.mismatch(image))
    else:
        assert np.array_equal(out, image) and np.array_equal(se, stderr) and info.unknowns == 0


def test_udim_tiles_meet_at_a_seam_even_where_the_uvs_run_on():
    # A 2 x 1 plane whose UVs run on from tile 1001 into 1002: in a UDIM image the edge at u = 1 is
    # looked up in tile 1001 from the left (columns 7 and, wrapped, 0 of that tile) and in tile 1002
    # from the right; in one image it is no seam.
    P = np.array([[0, 0, 0], [1, 0, 0], [2, 0, 0], [0, 1, 0], [1, 1, 0], [2, 1, 0]], float)
    F = np.array([[0, 1, 4], [0, 4, 3], [1, 2, 5], [1, 5, 4]])
    m = Mesh(P, F, P[F][:, :, :2].copy(), name="two tiles")
    assert G.seam_lookups(m, 8).edges == 0
    L = G.seam_lookups(m, 8, tiles=(1001, 1002))
    assert L.edges == 1 and L.shape == (2, 8, 8)
    tile_of = lambda tri: 0 if tri in (0, 1) else 1  # noqa: E731  (triangles 0, 1 lie in tile 1001)
    tiles = np.random.default_rng(2).random((2, 8, 8))
    diff = L.difference(tiles)
    for k in range(L.points):
        (ua, va), (ub, vb) = L.uv[k]
        ta, tb = tile_of(L.triangle[k, 0]), tile_of(L.triangle[k, 1])
        assert ta != tb
        slow = bilinear_lookup(tiles[ta], ua - ta, va) - bilinear_lookup(tiles[tb], ub - tb, vb)
        assert diff[k] == pytest.approx(slow, abs=1e-9)
    left = L.index[:, :4] if tile_of(L.triangle[0, 0]) == 0 else L.index[:, 4:]
    assert set(np.unique(left // 64)) == {0} and set(np.unique(left % 8)) == {0, 7}


# --- the fix --------------------------------------------------------------------------------------

def _dense_solution(values, stderr, mask, L, seam_weight, margin_weight):
    """The minimiser of fix_seams' objective over the texels the lookups read, as a dense weighted
    least-squares problem (rows: sqrt(weight) x (lookup A - lookup B) per point, sqrt(weight) x
    (x_i - y_i) per texel), texels with zero error held."""
    flat_v, flat_s, flat_m = values.reshape(-1).astype(float), stderr.reshape(-1).astype(float), mask.reshape(-1)
    texels = np.unique(L.index)
    free = texels[~(flat_m[texels] & (flat_s[texels] == 0))]
    col = {t: i for i, t in enumerate(free)}
    s_ref = np.median(flat_s[free][flat_m[free]])
    rows, rhs = [], []
    for k in range(L.points):
        row = np.zeros(len(free))
        const = 0.0
        for t, w in zip(L.index[k], L.weight[k]):
            if t in col:
                row[col[t]] += w
            else:
                const += w * flat_v[t]
        sw = np.sqrt(seam_weight * L.length[k]) / s_ref
        rows.append(sw * row)
        rhs.append(-sw * const)
    for i, t in enumerate(free):
        row = np.zeros(len(free))
        sw = 1 / flat_s[t] if flat_m[t] else np.sqrt(margin_weight) / s_ref
        row[i] = sw
        rows.append(row)
        rhs.append(sw * flat_v[t])
    x = np.linalg.lstsq(np.array(rows), np.array(rhs), rcond=None)[0]
    return free, x


def test_the_fix_is_the_least_squares_solution_of_its_objective():
    target, occ, _, _ = charts(width=24, grid=2, cell=10, gap=2)
    r = bake_ao(target, occ, resolution=24, samples=16, seed=3, margin=2, fix_seams=False)
    L = G.seam_lookups(target, 24)
    out, _, info = F.fix_seams(r.ao, r.stderr, r.mask, L, value_range=(-np.inf, np.inf), tolerance=1e-10)
    free, x = _dense_solution(r.ao, r.stderr, r.mask, L, F.SEAM_WEIGHT, F.MARGIN_WEIGHT)
    assert np.array_equal(np.sort(info.texels), free)
    np.testing.assert_allclose(out.reshape(-1)[free], x, atol=2e-6)


@pytest.fixture(scope="module")
def lid_bake():
    """The raw bake (the fix's input) of the lid over the charts."""
    target, occ, truth, covered = charts()
    r = bake_ao(target, occ, resolution=W, samples=16, seed=0, fix_seams=False)
    assert np.array_equal(r.mask, covered)
    return target, r, truth


def test_the_fix_changes_only_texels_a_seam_lookup_reads_and_holds_exact_ones(lid_bake):
    target, r, _ = lid_bake
    L = G.seam_lookups(target, W)
    out, se, info = F.fix_seams(r.ao, r.stderr, r.mask, L)
    read = np.zeros(W * W, bool)
    read[L.index.reshape(-1)] = True
    untouched = ~read.reshape(W, W)
    assert untouched.sum() > 3000
    assert np.array_equal(out[untouched].view(np.uint32), r.ao[untouched].view(np.uint32))
    assert np.array_equal(se[untouched].view(np.uint32), r.stderr[untouched].view(np.uint32))
    exact = r.mask & (r.stderr == 0)
    assert np.array_equal(out[exact], r.ao[exact]) and np.array_equal(se[exact], r.stderr[exact])
    changed = np.zeros(W * W, bool)
    changed[info.texels] = True
    assert not (changed & (exact | untouched).reshape(-1)).any()
    # The same input gives the same bits.
    again, _, _ = F.fix_seams(r.ao, r.stderr, r.mask, L)
    assert np.array_equal(again.view(np.uint32), out.view(np.uint32))


def test_the_fix_brings_the_mismatch_below_what_the_exact_map_shows(lid_bake):
    target, r, truth = lid_bake
    L = G.seam_lookups(target, W)
    out, _, info = F.fix_seams(r.ao, r.stderr, r.mask, L)
    exact_map = np.where(r.mask, truth, r.ao)  # the exact texels with the bake's margin
    assert info.before == pytest.approx(L.mismatch(r.ao))
    assert info.after == pytest.approx(L.mismatch(out))
    assert info.after < 0.05 * info.before and info.after < 0.25 * L.mismatch(exact_map)
    assert 0 < info.iterations < F.MAX_ITERATIONS and info.residual <= F.TOLERANCE


def test_texels_of_another_target_are_held():
    # (the raw bake: the fix's input; the margin texels belong to no target here, and are held too)
    target, occ, _, _ = charts()
    r = bake_ao(target, occ, resolution=W, samples=16, seed=1, fix_seams=False)
    L = G.seam_lookups(target, W)
    owner = np.where(r.mask, 0, -1)
    owner[:, W // 2:] = np.where(r.mask[:, W // 2:], 1, -1)  # the right-hand charts belong to target 1
    out, _, _ = F.fix_seams(r.ao, r.stderr, r.mask, L, owner=owner)
    other = owner == 1
    assert np.array_equal(out[other], r.ao[other])
    assert not np.array_equal(out[owner == 0], r.ao[owner == 0])


@pytest.mark.parametrize("occluder", ["lid", "box"])
@pytest.mark.parametrize("layout", ["apart", "touching"])
def test_the_fixed_map_error_is_honest_on_exact_scenes(occluder, layout):
    # Charts with margins between them (the fix moves mostly margin texels) and charts touching in
    # the image (no margin: the fix moves covered texels by up to the texel-scale difference across
    # the seam, far beyond their noise). z = (fixed - exact) / reported error over every covered
    # texel with an error, and over the covered texels the fix changed, pooled over 8 bakes.
    kw = dict(cell=28, gap=4) if layout == "apart" else dict(cell=32, gap=0)
    target, occ, truth, covered = charts(occluder=occluder, **kw)
    L = G.seam_lookups(target, W)
    z_all, z_changed, z_raw = [], [], []
    for seed in range(8):
        r = bake_ao(target, occ, resolution=W, samples=64, seed=seed, fix_seams=False)
        out, se, info = F.fix_seams(r.ao, r.stderr, r.mask, L)
        changed = np.zeros(W * W, bool)
        changed[info.texels] = True
        changed = changed.reshape(W, W) & covered
        pos = covered & (se > 0)
        z = (out - truth) / np.where(pos, se, 1)
        z_all.append(z[pos])
        z_changed.append(z[changed & pos])
        z_raw.append(((r.ao - truth) / np.where(r.stderr > 0, r.stderr, 1))[changed & pos])
        assert np.all(np.abs(out - truth)[covered & (se == 0)] < 1e-6)
    z_all, z_changed, z_raw = np.concatenate(z_all), np.concatenate(z_changed), np.concatenate(z_raw)
    # 8 x 3136-4096 texels (correlated in pools of a few): the estimated sd's own noise is about
    # 0.01. The changed texels, 8 x 160-380 of them at the charts' borders, where the bake's own
    # error is a little low (raw z sd 1.03-1.10 there, measured over 16 other seeds; fixed
    # 0.91-1.09): about 0.03-0.05, so the fixed error must be as honest as the bake's there, 0.05
    # (one to two of those) allowed.
    assert len(z_changed) > 1000
    assert 0.85 <= z_all.std() <= 1.15, z_all.std()
    assert 0.85 <= z_changed.std() <= z_raw.std() + 0.05, (z_changed.std(), z_raw.std())
    assert abs(z_changed.mean()) < 0.15, z_changed.mean()


# --- in the bake ----------------------------------------------------------------------------------

def test_a_bake_fixes_its_seams_after_the_margin_as_fix_seams_does():
    target, occ, _, _ = charts()
    raw = bake_ao(target, occ, resolution=W, samples=16, seed=5, fix_seams=False)
    r = bake_ao(target, occ, resolution=W, samples=16, seed=5)
    L = G.seam_lookups(target, W)
    ao, se, info = F.fix_seams(raw.ao, raw.stderr, raw.mask, L)
    assert np.array_equal(r.ao.view(np.uint32), ao.view(np.uint32))
    assert np.array_equal(r.stderr.view(np.uint32), se.view(np.uint32))
    assert np.array_equal(r.samples, raw.samples) and np.array_equal(r.mask, raw.mask)
    assert r.metadata["fix_seams"] is True and "fix_seams" not in raw.metadata
    assert r.report["seam_points"] == L.points and r.report["seam_texels"] == info.unknowns
    assert r.report["seam_mismatch_after"] == info.after < 0.05 * r.report["seam_mismatch_before"]
    assert "seam_points" not in raw.report


def test_the_fixed_map_is_the_same_bits_for_any_threads_tiles_and_processes():
    target, occ, _, _ = charts()
    kw = dict(resolution=W, samples=8, seed=2)
    base = bake_ao(target, occ, threads=1, **kw)
    for other in (dict(threads=2, tile_size=16), dict(threads=1, tile_size=(32, 16)), dict(workers=2, threads=1)):
        r = bake_ao(target, occ, **kw, **other)
        assert np.array_equal(r.ao.view(np.uint32), base.ao.view(np.uint32)), other
        assert np.array_equal(r.stderr.view(np.uint32), base.stderr.view(np.uint32)), other


def test_the_denoiser_comes_first_and_the_raw_map_stays_raw():
    target, occ, _, _ = charts()
    kw = dict(resolution=W, samples=16, seed=3, denoise=True)
    plain = bake_ao(target, occ, fix_seams=False, **kw)
    r = bake_ao(target, occ, **kw)
    assert np.array_equal(r.raw_ao, plain.raw_ao) and np.array_equal(r.raw_stderr, plain.raw_stderr)
    ao, se, _ = F.fix_seams(plain.ao, plain.stderr, plain.mask, G.seam_lookups(target, W))
    assert np.array_equal(r.ao, ao) and np.array_equal(r.stderr, se)


def test_each_quantity_of_a_maps_bake_is_fixed_on_its_own():
    from core import bake_maps

    target, occ, _, _ = charts()
    kw = dict(resolution=W, samples=8, seed=4, max_distance=0.5)
    maps = bake_maps(target, occ, quantities=("ao", "thickness"), **kw)
    for q in ("ao", "thickness"):
        alone = bake_ao(target, occ, quantity=q, **kw)
        assert np.array_equal(maps[q].ao, alone.ao) and np.array_equal(maps[q].stderr, alone.stderr), q
        assert maps[q].metadata["fix_seams"] is True


def test_udim_tiles_are_fixed_together_across_their_shared_edge():
    # The unit plane's halves in tiles 1001 and 1002, the UVs running on across u = 1: every tile a
    # bake of its own, the tile border a seam between them (a lookup just left of it reads its tile's
    # column 0, wrapped); fixed together once both are baked.
    from core import bake_udim

    P = np.array([[0, 0, 0], [.5, 0, 0], [1, 0, 0], [0, 1, 0], [.5, 1, 0], [1, 1, 0]], float)
    F_ = np.array([[0, 1, 4], [0, 4, 3], [1, 2, 5], [1, 5, 4]])
    UV = P[F_][:, :, :2] * [2.0, 1.0]
    plane = Mesh(P, F_, UV, name="two tiles")
    from seam_scenes import lid
    kw = dict(resolution=32, samples=16, seed=6)
    raw = bake_udim(plane, [lid()], fix_seams=False, **kw)
    r = bake_udim(plane, [lid()], **kw)
    L = G.seam_lookups(plane, 32, tiles=(1001, 1002))
    assert L.edges == 1 and not L.crease.any()
    assert L.mismatch(r.ao) < 0.05 * L.mismatch(raw.ao)
    ao, se, _ = F.fix_seams(raw.ao, raw.stderr, raw.mask, L)
    assert np.array_equal(r.ao, ao) and np.array_equal(r.stderr, se)
    for i, t in enumerate((1001, 1002)):
        assert np.array_equal(r.tiles[t].ao, r.ao[i]) and r.tiles[t].metadata["fix_seams"] is True
    assert r.report["seam_points"] == L.points


def test_in_an_atlas_a_targets_seams_never_move_another_targets_texels():
    # Two targets in one image: the charts squeezed into the left half (their seams), a plane in the
    # right half touching them (no seam of its own). Every texel the plane owns (covered or margin)
    # keeps its bits; the charts' seams are fixed.
    target, occ, _, _ = charts()
    left = Mesh(target.positions, target.triangles, target.uvs * [0.5, 1.0], name="charts")
    P = np.array([[2, 0, 0], [3, 0, 0], [3, 1, 0], [2, 1, 0]], float)
    F_ = np.array([[0, 1, 2], [0, 2, 3]])
    right = Mesh(P, F_, (P[F_][:, :, :2] - [2, 0]) * [0.5, 1.0] + [0.5, 0.0], name="plane")
    kw = dict(resolution=W, samples=16, seed=8)
    raw = bake_ao([left, right], occ, fix_seams=False, **kw)
    r = bake_ao([left, right], occ, **kw)
    assert r.report["seam_points"] > 0 and r.metadata["fix_seams"] is True
    plane_owned = r.owner == 1
    assert plane_owned.sum() > 0.3 * W * W and np.array_equal(r.owner, raw.owner)
    assert np.array_equal(r.ao[plane_owned], raw.ao[plane_owned])
    L = G.seam_lookups([left, right], W)
    assert L.mismatch(r.ao) < 0.1 * L.mismatch(raw.ao)


def test_texels_beyond_the_margin_keep_what_the_image_had():
    # The seam lookups read texels just outside the charts; the fix may move those the margin filled,
    # never the ones beyond it: with no margin every uncovered texel stays 0, as without Fix Seams (at
    # margin 1 the lookups here read no texel past it). The covered texels still take the fix, and
    # UDIM tiles keep the same rule.
    from core import bake_udim
    from core.geometry.margin import margin_texels

    target, occ, _, _ = charts()
    margin = 0
    kw = dict(resolution=W, samples=16, seed=9, margin=margin)
    raw = bake_ao(target, occ, fix_seams=False, **kw)
    r = bake_ao(target, occ, **kw)
    region = raw.mask.copy()
    region.reshape(-1)[margin_texels(raw.ao, raw.mask, margin)[0]] = True
    L = G.seam_lookups(target, W)
    read = np.zeros(W * W, bool)
    read[L.index.reshape(-1)] = True
    beyond = ~region & read.reshape(W, W)
    assert beyond.sum() > 20  # the lookups do read texels past this margin
    assert np.array_equal(r.ao[~region], raw.ao[~region])
    assert L.mismatch(r.ao) < 0.5 * L.mismatch(raw.ao)
    u = bake_udim(target, occ, **kw)
    assert np.array_equal(u.tiles[1001].ao[~region], raw.ao[~region])


@pytest.mark.parametrize("seed", range(4))
def test_within_margin_is_the_set_of_texels_the_margin_fills(seed):
    # Random islands in two planes, every margin from 0 to 5: the texels within_margin says the margin
    # reaches are exactly the covered ones and those core.geometry.margin fills (its ring walk).
    from core.geometry.margin import margin_texels

    rng = np.random.default_rng(seed)
    mask = rng.random((2, 23, 31)) < 0.03 + 0.05 * seed
    everything = np.arange(mask.size)
    for margin in range(6):
        want = mask.copy()
        for plane, m in zip(want, mask):
            plane.reshape(-1)[margin_texels(np.zeros(m.shape, np.float32), m, margin)[0]] = True
        got = F.within_margin(mask, everything, margin).reshape(mask.shape)
        assert np.array_equal(got, want), (seed, margin)
