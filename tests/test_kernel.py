"""What the baker traces, seen through its public ``on_rays`` hook: the rays are the texels' pattern
points through the warps, every sample is traced once, directions pass a chi-square test against
their pdf (about each sample's own shading normal), and split texels share their samples by area."""

import math

import numpy as np
import pytest

from core import Mesh, bake_ao, warps
from core.engine.patterns import TexelPattern
from core.engine.adaptive import replicate_samples
from core.base.request import BakeRequest
from core.engine.settings import BakeSettings, pattern_span
from chi2 import SUITE_ALPHA, chi2_test, sidak
from scenes import plane

W = 16
SOURCES = ["sobol", "halton", "stratified", "independent"]


def record(mesh, **kw):
    """Bake ``mesh`` and return every ray it traced, concatenated, with the result."""
    batches = []

    def keep(b):
        batch = {k: np.array(getattr(b, k)) for k in ("origins", "directions", "tfar", "occluded", "texels",
                                                       "samples")}
        batch["replicate"] = np.full(len(b.texels), b.replicate)
        batches.append(batch)

    r = bake_ao(mesh, threads=1, margin=0, on_rays=keep, **kw)
    return {k: np.concatenate([b[k] for b in batches]) for k in batches[0]}, r


class _Drawn:
    """A registry-like sampler whose draws are given (for the chi-square harness)."""

    def __init__(self, points, pdf, domain="hemisphere", dim=3):
        self.points, self.pdf, self.domain, self.dim = points, pdf, domain, dim

    def draw(self, n, rng):
        return self.points[:n]


@pytest.mark.parametrize("source", SOURCES)
@pytest.mark.parametrize("replicates", [1, 2, 3])
def test_every_sample_of_every_texel_is_traced_once(source, replicates):
    # 25 samples: with 2 replicates, replicate 0 takes 13 and replicate 1 takes 12; with 3, 9, 8, 8.
    rays, r = record(plane(), resolution=W, samples=25, source=source, replicates=replicates)
    key = (rays["texels"] * 8 + rays["replicate"]) * 1000 + rays["samples"]
    assert np.unique(key).size == key.size == W * W * 25
    for rep, cap in enumerate(replicate_samples(25, replicates)):
        assert set(np.unique(rays["samples"][rays["replicate"] == rep])) == set(range(cap))
    assert r.rays == key.size and np.all(r.samples == 25)


@pytest.mark.parametrize("source", SOURCES)
@pytest.mark.parametrize("distribution, samples", [("cosine", 32), ("uniform", 32), ("cosine", 26)])
def test_rays_are_the_patterns_points_through_the_warps(source, distribution, samples):
    # On a plane (UVs = xy, normal +z) the rays of texels inside one triangle must be exactly: origin
    # at the texel's corner plus (u2, u3) of the texel's pattern point, direction the distribution's
    # warp of (u0, u1) turned by the texel's own angle. A kernel that mixes up the pattern's
    # dimensions, the texel's keys or the warp fails here. 26 samples: 13 per replicate, one piece
    # per texel that the kernel gathers as aligned blocks of 8, 4 and 1 samples.
    rays, _ = record(plane(), resolution=W, samples=samples, source=source, distribution=distribution, seed=5)
    col, row = rays["texels"] % W, rays["texels"] // W
    simple = np.abs(col - row) > 1  # away from the plane's diagonal, where texels are split
    s = BakeSettings.of(BakeRequest(resolution=W, samples=samples, distribution=distribution, source=source, margin=0,
                                    seed=5, threads=1))
    pattern = TexelPattern(source, 5, s.replicate_samples, pool_points=s.pool_points())
    t, i, rep = rays["texels"][simple][:4000], rays["samples"][simple][:4000], rays["replicate"][simple][:4000]
    assert set(np.unique(rep)) == {0, 1}  # two replicates by default, each its own randomisation
    u = np.stack([pattern.points(np.array([a]), int(b), 1, replicate=int(c))[0, 0] for a, b, c in zip(t, i, rep)])
    # The baker works in a frame centred on the target and scaled to its size: the unit plane maps
    # to [-0.5, 0.5]^2, so compare in that frame.
    org = rays["origins"][simple][:4000]
    np.testing.assert_allclose(org[:, 0] + 0.5, ((t % W) + u[:, 2]) / W, atol=2e-6)
    np.testing.assert_allclose(org[:, 1] + 0.5, ((t // W) + u[:, 3]) / W, atol=2e-6)
    assert np.all(org[:, 2] > 0) and np.all(org[:, 2] < 1e-5)  # pushed off the surface, barely
    if distribution == "cosine":
        local = warps.sample_cosine_hemisphere_polar(u[:, :2])
    else:
        local = np.stack(warps.uniform_hemisphere_xyz(u[:, 0], u[:, 1]), axis=1)
    c, s = np.zeros(len(t)), np.zeros(len(t))
    for r in (0, 1):
        keys = pattern.keys(t[rep == r], replicate=r)
        c[rep == r], s[rep == r] = keys.cos_turn, keys.sin_turn
    want = np.stack([c * local[:, 0] - s * local[:, 1], s * local[:, 0] + c * local[:, 1], local[:, 2]], axis=1)
    np.testing.assert_allclose(rays["directions"][simple][:4000], want, atol=2e-6)


CHI2_CASES = [("cosine", "flat"), ("uniform", "flat"), ("cosine", "smooth"), ("uniform", "smooth")]
CHI2_ALPHA = sidak(SUITE_ALPHA, 64)


def bumpy_plane():
    """The unit plane as a 4 x 4 grid of quads whose corner normals lean by up to 25 degrees in
    different directions: the shading normal changes across every triangle."""
    n = 4
    t = np.linspace(0.0, 1.0, n + 1)
    X, Y = np.meshgrid(t, t)
    P = np.stack([X.ravel(), Y.ravel(), np.zeros(X.size)], axis=1)
    i = np.arange(n)
    a = (i[None, :] + (n + 1) * i[:, None]).ravel()
    F = np.concatenate([np.stack([a, a + 1, a + n + 2], 1), np.stack([a, a + n + 2, a + n + 1], 1)])
    rng = np.random.default_rng(3)
    lean = rng.uniform(-0.45, 0.45, size=(len(P), 2))
    vn = np.concatenate([lean, np.ones((len(P), 1))], axis=1)
    vn /= np.linalg.norm(vn, axis=1, keepdims=True)
    return Mesh(P, F, uvs=P[F][:, :, :2], normals=vn[F], name="bumpy"), vn


def shading_normal_at(points, mesh, vn):
    """The interpolated shading normal at points on the bumpy plane (its z = 0 frame)."""
    P = mesh.positions
    out = np.zeros((len(points), 3))
    done = np.zeros(len(points), bool)
    for f in mesh.triangles:
        a, b, c = P[f, :2]
        m = np.array([[b[0] - a[0], c[0] - a[0]], [b[1] - a[1], c[1] - a[1]]])
        l1, l2 = np.linalg.solve(m, (points[:, :2] - a).T)
        l0 = 1 - l1 - l2
        inside = (l0 > -1e-9) & (l1 > -1e-9) & (l2 > -1e-9) & ~done
        n = l0[:, None] * vn[f[0]] + l1[:, None] * vn[f[1]] + l2[:, None] * vn[f[2]]
        out[inside] = n[inside]
        done |= inside
    assert done.all()
    return out / np.linalg.norm(out, axis=1, keepdims=True)


@pytest.mark.parametrize("distribution, shading", CHI2_CASES)
def test_traced_directions_follow_their_pdf_about_each_samples_normal(distribution, shading):
    # Every direction the baker hands to Embree (those below the surface too: they are samples of
    # the same distribution, only not traced), in the frame of the shading normal at its origin,
    # against cos(theta)/pi or 1/(2 pi) with the chi-square harness of the warps.
    if shading == "flat":
        mesh, normal = plane(), None
    else:
        mesh, vn = bumpy_plane()
    rays, _ = record(mesh, resolution=64, samples=64, distribution=distribution, seed=9)
    d = rays["directions"].astype(np.float64)
    d /= np.linalg.norm(d, axis=1, keepdims=True)
    if shading == "flat":
        n = np.broadcast_to([0.0, 0.0, 1.0], d.shape)
    else:
        # Origins are in the baker's frame (centred, scaled): back to the unit plane.
        n = shading_normal_at(rays["origins"].astype(np.float64) + [0.5, 0.5, 0.0], mesh, vn)
    local = np.stack([np.einsum("ij,ij->i", d, s) for s in warps.orthonormal_basis(n)] + [np.einsum("ij,ij->i", d, n)], 1)
    pdf = warps.cosine_hemisphere_pdf if distribution == "cosine" else warps.uniform_hemisphere_pdf
    p, msg = chi2_test(_Drawn(local, pdf), len(local), None)
    assert p > CHI2_ALPHA, f"{distribution}, {shading}: p = {p:.3g} ({msg}, {len(local)} rays)"
    if shading == "smooth":
        below = rays["tfar"] == 0
        assert below.any(), "the leaning normals should send some directions below the face"
        assert np.all(d[below, 2] <= 1e-6) and np.all(d[~below, 2] > -1e-6)


def test_the_chi_square_of_traced_rays_can_fail():
    # The same harness rejects cosine directions read against the uniform pdf, and directions taken
    # about the face normal instead of each sample's shading normal on the bumpy plane.
    rays, _ = record(plane(), resolution=32, samples=64, seed=9)
    d = rays["directions"].astype(np.float64)
    d /= np.linalg.norm(d, axis=1, keepdims=True)
    p, _ = chi2_test(_Drawn(d, warps.uniform_hemisphere_pdf), len(d), None)
    assert p < CHI2_ALPHA
    mesh, vn = bumpy_plane()
    rays, _ = record(mesh, resolution=32, samples=64, seed=9)
    d = rays["directions"].astype(np.float64)
    d /= np.linalg.norm(d, axis=1, keepdims=True)
    keep = d[:, 2] > 0
    p, _ = chi2_test(_Drawn(d[keep], warps.cosine_hemisphere_pdf), int(keep.sum()), None)
    assert p < CHI2_ALPHA


def seamed_plane():
    """The unit plane with a UV seam along its diagonal: triangle 1's UVs shrink towards its centroid
    by a factor 1 - 1e-7, so the diagonal is an island border and the texels it crosses are split
    (clipped, their samples shared by area), not located; positions in space are the plane's."""
    p = plane()
    uv = p.uvs.copy()
    c = uv[1].mean(axis=0)
    uv[1] = c + (uv[1] - c) * (1 - 1e-7)
    return Mesh(p.positions, p.triangles, uv, name="seamed")


def test_split_texels_share_samples_by_area_and_cover_each_piece():
    # The seamed plane's diagonal splits texels into two triangles of known area. Systematic
    # sampling gives each piece its area's share of every texel's samples to within one, and the
    # samples of a piece lie inside it.
    samples = 64
    rays, _ = record(seamed_plane(), resolution=W, samples=samples, seed=2)
    x = (rays["origins"][:, 0] + 0.5) * W
    y = (rays["origins"][:, 1] + 0.5) * W
    col, row = rays["texels"] % W, rays["texels"] // W
    assert np.all((x >= col - 1e-4) & (x <= col + 1 + 1e-4) & (y >= row - 1e-4) & (y <= row + 1 + 1e-4))
    diag = col == row
    below = (y < x)  # the triangle (0, 1, 2) of the plane lies below the diagonal y = x
    counts = np.bincount(rays["texels"][diag], weights=below[diag], minlength=W * W)[np.arange(W) * (W + 1)]
    assert np.all(np.abs(counts - samples / 2) <= 1), counts


def test_directions_below_the_face_count_as_occluded():
    # A plane whose shading normal leans by alpha from its face normal: with nothing around, the
    # directions of the cosine lobe about the shading normal that dip below the face (a fraction
    # (1 - cos alpha) / 2, by the sphere construction: d ~ n + v, v uniform, below iff g.v < -cos alpha)
    # count as occluded, so AO = (1 + cos alpha) / 2, the same everywhere.
    alpha = math.radians(35)
    n = np.array([math.sin(alpha), 0.0, math.cos(alpha)])
    p = plane()
    lean = Mesh(p.positions, p.triangles, p.uvs, normals=np.broadcast_to(n, (2, 3, 3)), name="lean")
    r = bake_ao(lean, resolution=16, samples=256, margin=0, seed=4, source="independent")
    exact = (1 + math.cos(alpha)) / 2
    z = (r.ao - exact) / r.stderr
    assert abs(z.mean()) < 4 / math.sqrt(z.size) and 0.75 < z.var() < 1.3, (r.ao.mean(), exact, z.var())


def test_split_texels_share_samples_by_area_on_average_over_seeds():
    # A texel split into pieces of area fractions w gets count * w samples in each on average over
    # the per-texel random numbers (to within one in every bake): the allocation is unbiased. A
    # resolution of 16 x 13 makes the seamed plane's diagonal cut texels unevenly.
    from core.geometry.raster import prepare, rasterize_tile

    w_, h_, samples, bakes = 16, 13, 4, 48
    frag = rasterize_tile(prepare(seamed_plane(), w_, h_), np.array([0, 1]), w_, h_, 0, 0, w_, h_)
    lower = {}
    for k in np.flatnonzero(frag.full_tri == -1):  # texels the diagonal cuts (and the seam's other edges)
        tri = frag.sub_tri[frag.sub_start[k]:frag.sub_start[k + 1]]
        share = np.diff(np.concatenate([[0.0], frag.sub_cdf[frag.sub_start[k]:frag.sub_start[k + 1]]]))
        lower[frag.texels[k]] = share[tri == 0].sum()  # area fraction of triangle 0
    # Each replicate allocates its own samples (from a seed of its own): count per (texel, replicate).
    counts = {(t, r): [] for t in lower for r in (0, 1)}
    for seed in range(bakes):
        rays, _ = record(seamed_plane(), resolution=(w_, h_), samples=2 * samples, seed=seed)
        x = (rays["origins"][:, 0] + 0.5) * w_
        y = (rays["origins"][:, 1] + 0.5) * h_
        in0 = y * w_ < x * h_  # triangle 0 lies below the diagonal from (0, 0) to (W, H)
        for t, r in counts:
            counts[t, r].append(int(in0[(rays["texels"] == t) & (rays["replicate"] == r)].sum()))
    lower = {(t, r): lower[t] for t, r in counts}
    frac = np.array([samples * lower[t] for t in lower])
    mean = np.array([np.mean(counts[t]) for t in lower])
    spread = np.array([max(np.ptp(counts[t]), 0) for t in lower])
    assert np.all(spread <= 1)  # always within one of its share
    sd = np.sqrt(np.maximum((frac % 1) * (1 - frac % 1), 1e-12) / bakes)
    z = (mean - frac) / sd
    uneven = (frac % 1 > 0.1) & (frac % 1 < 0.9)
    assert uneven.sum() >= 5 and np.all(np.abs(z[uneven]) < 4.5), (z[uneven], frac[uneven])


def test_smooth_shading_keeps_the_ao_distance():
    # The truncated cone (plane under a lid at h = 0.3, AO distance 0.5: AO = (h / d)^2 = 0.36) with
    # shading normals that lean by up to 0.01 rad: the smooth path's directions are not unit length,
    # and the rays must still reach exactly 0.5 (a lean of 0.01 changes the AO by well under 1e-3).
    rng = np.random.default_rng(6)
    p = plane()
    n = np.concatenate([rng.uniform(-0.01, 0.01, (2, 3, 2)), np.ones((2, 3, 1))], axis=2)
    smooth = Mesh(p.positions, p.triangles, p.uvs, normals=n, name="smooth")
    lid = Mesh(np.array([[-1.0, -1.0, 0.3], [2.0, -1.0, 0.3], [2.0, 2.0, 0.3], [-1.0, 2.0, 0.3]]),
               np.array([[0, 1, 2], [0, 2, 3]]), name="lid")
    r = bake_ao(smooth, [lid], resolution=16, samples=256, max_distance=0.5, margin=0, source="independent", seed=2)
    z = (r.ao - 0.36) / r.stderr
    assert abs(z.mean()) < 4 / math.sqrt(z.size) + 0.1 and 0.75 < z.var() < 1.3, (r.ao.mean(), z.mean(), z.var())


@pytest.mark.parametrize("kw", [dict(), dict(distribution="uniform", source="halton"),
                                dict(falloff=1.0, ignore_backfaces=True, source="stratified"),
                                dict(samples=128, min_samples=8, target_error=0.05)])
def test_smooth_split_and_adaptive_bakes_are_bit_identical_for_any_threads_tiles_and_chunks(kw):
    # The leaning-normal grid (smooth path, texels split along every triangle edge) under a lid with
    # a finite distance: every path of the kernel, traced in different groupings, gives the same bits.
    mesh, _ = bumpy_plane()
    lid = Mesh(np.array([[0.1, 0.1, 0.2], [0.8, 0.2, 0.25], [0.7, 0.9, 0.3]]), np.array([[0, 1, 2]]), name="lid")
    args = dict(resolution=24, samples=32, max_distance=0.6, margin=0, seed=8)
    args.update(kw)
    a = bake_ao(mesh, [lid], threads=1, **args)
    b = bake_ao(mesh, [lid], threads=2, tile_size=8, chunk_rays=333, **args)
    for name in ("ao", "stderr", "samples", "mask"):
        assert np.array_equal(getattr(a, name), getattr(b, name)), name


def test_replicates_allocate_a_split_texels_samples_independently():
    # Each replicate is an independent randomisation, the share of a split texel's samples between
    # its pieces included: replicate 1 does not repeat replicate 0's allocation.
    rays, _ = record(plane(), resolution=(16, 13), samples=8, seed=1)
    x = (rays["origins"][:, 0] + 0.5) * 16
    y = (rays["origins"][:, 1] + 0.5) * 13
    in0 = y * 16 < x * 13
    split = np.unique(rays["texels"][np.abs(x - y * 16 / 13) < 2])
    counts = np.array([[int(in0[(rays["texels"] == t) & (rays["replicate"] == r)].sum()) for r in (0, 1)]
                       for t in split])
    assert len(split) > 10 and np.mean(counts[:, 0] != counts[:, 1]) > 0.1



@pytest.mark.parametrize("locate", [False, True])
def test_an_adaptive_rounds_per_texel_counts_allocate_as_each_texel_alone(locate):
    """One pass per adaptive round: allocating every texel's own [start, start + count) at once gives
    each texel exactly the pieces it gets alone: split texels (clipped: their units share by hash)
    and texels of one unit (a whole aligned power-of-two block or not)."""
    from core.geometry.raster import prepare, rasterize_tile
    from core.geometry.surface import SurfaceTable, allocate, build_units

    mesh = plane()
    uvtris = prepare(mesh, 16, 16)
    units = build_units(rasterize_tile(uvtris, np.arange(len(mesh.triangles)), 16, 16, 0, 0, 16, 16, locate=locate),
                        SurfaceTable.build(mesh, uvtris), 16)
    n_tex = len(units.first) - 1
    assert np.any(np.diff(units.first) > 1) != locate  # the diagonal's texels: split, or located
    rng = np.random.default_rng(4)
    texels = np.sort(rng.choice(n_tex, n_tex // 2 + 4, replace=False))
    start = rng.integers(0, 1000, len(texels))
    count = rng.integers(1, 200, len(texels))  # odd counts: a split texel's share depends on its hash
    # and aligned power-of-two blocks for half the texels of one unit (one piece each)
    whole = (rng.random(len(texels)) < 0.5) & (np.diff(units.first)[texels] == 1)
    count[whole] = 2 ** rng.integers(0, 8, whole.sum())
    start[whole] = count[whole] * rng.integers(0, 8, whole.sum())
    ids = np.arange(n_tex, dtype=np.uint64) * np.uint64(7) + np.uint64(3)
    together = allocate(units, texels, start, count, np.uint64(11), ids)
    alone = [allocate(units, texels[i:i + 1], int(start[i]), int(count[i]), np.uint64(11), ids)
             for i in range(len(texels))]
    key = lambda u, f, z: sorted(zip(u.tolist(), f.tolist(), z.tolist()))  # noqa: E731
    assert key(*together) == key(*(np.concatenate(c) for c in zip(*alone)))
    # And each texel's pieces cover exactly its own samples [start, start + count).
    owner = units.texel[together[0]]
    for i, t in enumerate(texels):
        mine = owner == t
        assert together[2][mine].sum() == count[i]
        assert together[1][mine].min() == start[i] and (together[1] + together[2])[mine].max() == start[i] + count[i]


@pytest.mark.parametrize("locate", [False, True])
def test_every_units_map_takes_the_unit_square_onto_its_piece(locate):
    """Units' maps (A0 + A1 u + A2 v, B0 + B1 u + B2 v), in the texel space of the unit's triangle
    (its first corner at 0): a square's take (0, 0), (1, 0) and (0, 1) to its texel's corners (a
    located texel's the same, less its translation, which each candidate has of its own), a
    sub-triangle's to its corners 2, 0 and 1 (Heitz's weights of corners 0 and 1), whichever
    consumer specialises a kind (the kernel reads a square's translation alone)."""
    from core.geometry.raster import prepare, rasterize_tile
    from core.geometry.surface import SQUARE, TRIANGLE, SurfaceTable, build_units

    mesh = plane()
    w, h = 16, 13
    uvtris = prepare(mesh, w, h)
    table = SurfaceTable.build(mesh, uvtris)
    frag = rasterize_tile(uvtris, np.arange(len(mesh.triangles)), w, h, 0, 0, w, h, locate=locate)
    units = build_units(frag, table, w)
    coef = units.coef
    origin = table.origin[units.tri]

    def at(u, v):
        return (np.stack([coef[:, 0] + coef[:, 1] * u + coef[:, 2] * v,
                          coef[:, 3] + coef[:, 4] * u + coef[:, 5] * v], 1) + origin)

    tex = frag.texels[units.texel]
    corner = np.stack([tex % w, tex // w], 1).astype(float)
    square = units.kind != TRIANGLE
    assert square.sum() > 10 and np.any(units.kind == SQUARE)
    assert ((~square).sum() > 10) != locate  # the diagonal's texels: split, or located squares
    # A located texel's translation is per candidate (cand_coef); its square's linear part is here.
    own = units.kind == SQUARE
    for (u, v), step in (((0, 0), (0, 0)), ((1, 0), (1, 0)), ((0, 1), (0, 1))):
        np.testing.assert_allclose(at(u, v)[own], corner[own] + step, atol=1e-9)
        np.testing.assert_allclose((at(u, v) - at(0, 0))[square], np.broadcast_to(step, (square.sum(), 2)), atol=1e-9)
    sub = np.flatnonzero(~square)
    piece = frag.sub_start[units.texel[sub]] + (sub - units.first[units.texel[sub]])
    for (u, v), k in (((0, 0), 2), ((1, 0), 0), ((0, 1), 1)):
        np.testing.assert_allclose(at(u, v)[sub], frag.sub_xy[piece, k], atol=1e-9)
