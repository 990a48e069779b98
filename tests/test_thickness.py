"""The thickness map (core.engine.thickness): a slab's and a sphere's closed forms, the open-mesh and terminator
rules on a plane, the rays' directions about the inverted normal (chi-square), selected to active, the
worker processes, and bad values refused by name."""

import math

import numpy as np
import pytest

from core import Mesh, SettingsError, bake_ao, warps
from core.montecarlo.stats import normal_quantile
from core import bake_vertex_ao
from chi2 import SUITE_ALPHA, chi2_test, sidak
from scenes import box, plane

D = 0.5       # max distance
DEPTH = 0.2   # the slab's thickness
HALF = 5.0    # the slab's half width
N = 256


def slab(depth=DEPTH, name="slab"):
    """A wide closed box, z in [0, depth], its top face mapped onto the whole UV square; the other
    faces have no area in the UV map (skipped)."""
    b = box((-HALF, -HALF, 0.0), (HALF, HALF, depth), name=name)
    P, F = b.positions, b.triangles
    corners = P[F]
    top = np.all(corners[:, :, 2] == depth, axis=1)
    uv = np.zeros(corners.shape[:2] + (2,))
    uv[top] = (corners[top][:, :, :2] + HALF) / (2 * HALF)
    return Mesh(P, F, uv, name=name)


def interior(r, margin=D):
    """Texels of the top face farther than ``margin`` from the slab's sides (their rays cannot reach a side)."""
    h, w = r.ao.shape
    x = (np.arange(w) + 0.5) / w * 2 * HALF - HALF
    y = (np.arange(h) + 0.5) / h * 2 * HALF - HALF
    far = (np.abs(x)[None, :] < HALF - margin - 2 * HALF / w) & (np.abs(y)[:, None] < HALF - margin - 2 * HALF / h)
    return far & r.mask


def record(target, **kw):
    batches = []

    def keep(b):
        batches.append({k: np.array(getattr(b, k)) for k in ("origins", "directions", "tfar", "texels")})

    r = bake_ao(target, threads=1, margin=0, on_rays=keep, **kw)
    return {k: np.concatenate([b[k] for b in batches]) for k in batches[0]}, r


#: Variance of a texel's estimate, at most GAMMA times the independent-sample variance p (1 - p) / n:
#: exactly 1 for independent samples; jittered (stratified) sampling is never above it; an
#: Owen-scrambled (0, m, 2)-net (Sobol's direction dimensions) at most 2 times it (Owen 1997, base 2,
#: s = 2); Halton's digit permutations have no such theorem: its measured variance here is far below
#: (the slab's indicator depends on the direction alone, a smooth boundary in the disk).
GAMMA = {"independent": 1.0, "stratified": 1.0, "sobol": 2.0, "halton": 2.0}


def check_share(values, p, n, source, alpha, sharing=None):
    """Each value a mean of n terms in {0, 1} with mean p: within the Sidak interval of the variance
    bound. For independent samples also their mean, whose variance is p (1 - p) / n times
    ``sharing`` / m (see :func:`sharing`; 1 when every value has draws of its own)."""
    values = np.asarray(values, float)
    sd = np.sqrt(GAMMA[source] * p * (1 - p) / n)
    m = values.size
    z = (values - p) / sd
    crit = normal_quantile(1 - sidak(alpha, m + 1) / 2)
    assert np.abs(z).max() < crit, (source, np.abs(z).max())
    zt = (values.mean() - p) / (sd * math.sqrt((1.0 if sharing is None else sharing) / m))
    if source == "independent":
        assert abs(zt) < crit, zt
    return float(np.abs(z).max()), float(zt)


def sharing(rays, ids, normals):
    """Texels (or points) draw their directions from a pool of patterns, each turned by the texel's
    own angle about its normal: where the baked value depends on the angle to the normal alone (the
    slab, the sphere) texels that drew the same pattern give the same value, and the values are not
    independent. Groups texels ``ids`` by the sorted cosines of their rays to ``normals`` (one per
    id, unit) and returns sum(group size^2) / m: the factor by which the mean's variance exceeds
    that of m independent values."""
    d = rays["directions"].astype(np.float64)
    d /= np.linalg.norm(d, axis=1, keepdims=True)
    pos = {int(t): i for i, t in enumerate(ids)}
    sel = np.flatnonzero(np.isin(rays["texels"], ids))
    row = np.array([pos[int(t)] for t in rays["texels"][sel]])
    cos = np.einsum("ij,ij->i", d[sel], normals[row])
    order = np.lexsort((cos, row))
    row, cos = row[order], np.rint(cos[order] * 1e4).astype(np.int64)
    bounds = np.flatnonzero(np.diff(row)) + 1
    keys = [c.tobytes() for c in np.split(cos, bounds)]
    _, counts = np.unique(keys, return_counts=True)
    return float((counts.astype(float) ** 2).sum() / len(ids))


@pytest.mark.parametrize("source", ["sobol", "stratified", "independent", "halton"])
def test_a_slab_lets_the_share_1_minus_d_over_D_squared_of_its_rays_meet_the_far_side(source):
    """Cosine rays about the inverted normal meet the far side at distance d / cos(theta) <= D when
    cos(theta) >= d / D: probability 1 - (d / D)^2. The map is the rays that do not: (d / D)^2."""
    rays, r = record(slab(), resolution=32, samples=N, max_distance=D, quantity="thickness", source=source,
                     replicates=1, seed=5)
    inner = interior(r)
    assert inner.sum() > 400
    p = (DEPTH / D) ** 2
    ids = np.flatnonzero(inner.reshape(-1))
    share = sharing(rays, ids, np.tile([0.0, 0.0, -1.0], (len(ids), 1))) if source == "independent" else None
    check_share(r.ao[inner], p, N, source, SUITE_ALPHA / 8, share)
    assert r.metadata["quantity"] == "thickness"


def test_a_slab_thinner_than_the_distance_reads_darker_than_a_thicker_one():
    thin = bake_ao(slab(0.1), resolution=16, samples=64, max_distance=D, quantity="thickness", margin=0)
    thick = bake_ao(slab(0.4), resolution=16, samples=64, max_distance=D, quantity="thickness", margin=0)
    assert thin.ao[interior(thin)].mean() < 0.1 < 0.5 < thick.ao[interior(thick)].mean()


def uv_sphere(radius=1.0, n_lon=96, n_lat=48):
    """A closed UV sphere, outward winding, with exact radial corner normals."""
    lat = np.linspace(0, math.pi, n_lat + 1)[1:-1]
    lon = np.linspace(0, 2 * math.pi, n_lon, endpoint=False)
    ring = np.stack([np.sin(lat)[:, None] * np.cos(lon)[None], np.sin(lat)[:, None] * np.sin(lon)[None],
                     np.cos(lat)[:, None] * np.ones_like(lon)[None]], -1).reshape(-1, 3)
    P = np.concatenate([[[0, 0, 1]], ring, [[0, 0, -1]]]) * radius
    F = []
    idx = lambda i, j: 1 + i * n_lon + j % n_lon  # noqa: E731
    for j in range(n_lon):
        F.append([0, idx(0, j), idx(0, j + 1)])
        for i in range(n_lat - 2):
            F += [[idx(i, j), idx(i + 1, j), idx(i + 1, j + 1)], [idx(i, j), idx(i + 1, j + 1), idx(i, j + 1)]]
        F.append([len(P) - 1, idx(n_lat - 2, j + 1), idx(n_lat - 2, j)])
    F = np.array(F)
    normals = P[F] / radius
    return Mesh(P, F, normals=normals, name="sphere")


def test_a_spheres_interior_has_its_closed_form():
    """From a point of a sphere of radius R, the ray at angle theta to the inward normal leaves it
    after the chord 2 R cos(theta): it meets the far side within D when cos(theta) <= D / 2R, with
    cosine-weighted probability (D / 2R)^2. The map: T = 1 - (D / 2R)^2 (D < 2R). Checked at the
    vertices (points on the sphere itself, radial normals). The mesh's facets lie at most
    delta = R (1 - cos(pi / 48)) (5.4e-4 R) inside the sphere, which shortens a chord at angle theta
    by at most delta / cos(theta) and moves the threshold cosine c = D / 2R by at most
    delta / (2 R c): T by at most 2 c of that, delta / R. The mean's allowance is twice it."""
    R, dist = 1.0, 1.2
    s = uv_sphere(R)
    batches = []
    r = bake_vertex_ao(s, samples=N, max_distance=dist, quantity="thickness", source="independent", replicates=1,
                       seed=3, threads=1,
                       on_rays=lambda b: batches.append({k: np.array(getattr(b, k)) for k in ("directions", "texels")}))
    rays = {k: np.concatenate([b[k] for b in batches]) for k in batches[0]}
    p = 1.0 - (dist / (2 * R)) ** 2
    ids, first = np.unique(r.unit, return_index=True)
    values = r.ao[first].astype(float)
    # Each point's inward normal: its vertex's radial normal, exactly the one its directions turn about.
    share = sharing(rays, ids, -s.positions[s.triangles.reshape(-1)[first]] / R)
    sd = math.sqrt(p * (1 - p) / N)
    crit = normal_quantile(1 - sidak(SUITE_ALPHA / 8, values.size + 1) / 2)
    assert np.abs(values - p).max() < crit * sd
    facet = 2.0 * (1 - math.cos(math.pi / 48))
    assert abs(values.mean() - p) < crit * sd * math.sqrt(share / values.size) + facet, values.mean() - p
    # Beyond the diameter every ray meets the far side.
    r = bake_vertex_ao(s, samples=32, max_distance=2.5 * R, quantity="thickness")
    assert r.ao.max() < 0.05


@pytest.mark.parametrize("tilt", [0.0, 40.0])
def test_an_open_plane_is_white_and_directions_leaving_through_it_count_as_thin(tilt):
    """A single plane (no far side): rays into it leave without meeting anything: T = 1. With corner
    normals tilted by alpha from the face, the share of cosine directions about the inverted normal
    that point out through the face is the tilted plane's ground view factor (1 - cos alpha) / 2;
    they count as meeting the surface at once: T = (1 + cos alpha) / 2."""
    a = math.radians(tilt)
    pl = plane()
    n = np.array([math.sin(a), 0.0, math.cos(a)])
    pl = Mesh(pl.positions, pl.triangles, pl.uvs, normals=np.broadcast_to(n, (2, 3, 3)).copy(), name="tilted")
    r = bake_ao(pl, resolution=16, samples=N, quantity="thickness", source="independent", replicates=1, margin=0,
                seed=2)
    p = (1 + math.cos(a)) / 2
    if tilt == 0:
        assert np.all(r.ao == 1.0)
    else:
        check_share(r.ao[r.mask], p, N, "independent", SUITE_ALPHA / 8)


CHI2_ALPHA = sidak(SUITE_ALPHA, 64)


@pytest.mark.parametrize("distribution", ["cosine", "uniform"])
@pytest.mark.parametrize("smooth", [False, True])
def test_directions_follow_their_pdf_about_the_inverted_normal(distribution, smooth):
    """Every ray of a thickness bake of a plane facing +z, in the frame of -z, against cos(theta)/pi
    (or 1/(2 pi)); read about +z the same directions fail (the harness can tell). The origins lie
    below the plane (pushed into the mesh)."""
    pl = plane()
    if smooth:
        pl = Mesh(pl.positions, pl.triangles, pl.uvs, normals=np.broadcast_to([0.0, 0.0, 1.0], (2, 3, 3)).copy())
    rays, r = record(pl, resolution=32, samples=64, quantity="thickness", distribution=distribution, seed=9)
    d = rays["directions"].astype(np.float64)
    d /= np.linalg.norm(d, axis=1, keepdims=True)
    assert np.all(rays["origins"][:, 2] < 0)

    def p_value(normal):
        nn = np.broadcast_to(normal, d.shape)
        local = np.stack([np.einsum("ij,ij->i", d, s) for s in warps.orthonormal_basis(nn)]
                         + [np.einsum("ij,ij->i", d, nn)], 1)
        pdf = warps.cosine_hemisphere_pdf if distribution == "cosine" else warps.uniform_hemisphere_pdf

        class Drawn:
            domain, dim, points = "hemisphere", 3, local

            def __init__(self):
                self.pdf = pdf

            def draw(self, count, rng):
                return self.points[:count]

        return chi2_test(Drawn(), len(local), None)[0]

    assert p_value(np.array([0.0, 0.0, -1.0])) > CHI2_ALPHA
    assert p_value(np.array([0.0, 0.0, 1.0])) < CHI2_ALPHA


def test_selected_to_active_bakes_the_high_polys_thickness():
    """A low plane over the slab's top: the points it matches on the slab take the slab's thickness;
    an occluder (a lid) plays no part."""
    low = plane(-1.0, -1.0, 1.0, 1.0, z=DEPTH + 0.05, name="low")
    lid = plane(-2.0, -2.0, 2.0, 2.0, z=DEPTH + 0.1, uv=False, name="lid")
    kw = dict(resolution=16, samples=N, max_distance=D, quantity="thickness", source="independent", replicates=1,
              margin=0, seed=6, highpoly=[box((-HALF, -HALF, 0.0), (HALF, HALF, DEPTH), name="slab")],
              extrusion=0.1)
    r = bake_ao(low, [lid], **kw)
    assert r.mask.all()
    p = (DEPTH / D) ** 2
    # Each point carries a block of directions (not independent of each other in position, but the
    # slab's thickness is the same everywhere: the terms are independent draws of the direction).
    check_share(r.ao, p, N, "independent", SUITE_ALPHA / 8)
    assert np.array_equal(r.ao, bake_ao(low, **kw).ao)


def test_the_target_alone_occludes():
    # An occluder right inside the slab (a plane through its middle) changes nothing.
    mid = plane(-HALF, -HALF, HALF, HALF, z=DEPTH / 2, uv=False, name="mid")
    kw = dict(resolution=16, samples=32, max_distance=D, quantity="thickness", margin=0)
    assert np.array_equal(bake_ao(slab(), [mid], **kw).ao, bake_ao(slab(), **kw).ao)


def test_workers_give_the_bits_of_one_process():
    kw = dict(resolution=32, samples=32, max_distance=D, quantity="thickness", margin=2)
    one = bake_ao(slab(), workers=1, **kw)
    two = bake_ao(slab(), workers=2, **kw)
    for f in ("ao", "stderr", "samples", "mask"):
        assert np.array_equal(getattr(one, f), getattr(two, f)), f
    assert two.metadata["quantity"] == "thickness"


def test_adaptive_sampling_and_the_error_map_work_as_for_ao():
    r = bake_ao(slab(), resolution=16, samples=256, min_samples=16, target_error=0.05, max_distance=D,
                quantity="thickness", margin=0)
    inner = interior(r)
    assert np.all(r.stderr[inner] > 0) and r.samples[inner].min() >= 16 and r.samples[inner].max() <= 256


@pytest.mark.parametrize("kw, message", [
    (dict(quantity="thick"), "quantity"),
    (dict(quantity=None), "quantity"),
    (dict(quantity="thickness", ground="auto"), "ground"),
    (dict(quantity="thickness", ignore_backfaces=True), "ignore_backfaces"),
    (dict(quantity="thickness", bent_normals=True), "bent normals"),
])
def test_bad_values_are_refused_by_name(kw, message):
    with pytest.raises(SettingsError, match=message):
        bake_ao(slab(), resolution=16, samples=8, **kw)
    with pytest.raises(SettingsError, match=message):
        bake_vertex_ao(slab(), samples=8, **kw)


def test_udim_tiles_and_a_falloff_bake_thickness_too():
    from core import bake_udim

    r = bake_udim(slab(), resolution=16, samples=64, max_distance=D, quantity="thickness", margin=0)
    part = r.tiles[1001]
    assert part.metadata["quantity"] == "thickness"
    assert abs(part.ao[interior(part)].mean() - (DEPTH / D) ** 2) < 0.05
    # With a falloff, a far side met at t occludes by (1 - t / D)^p: between the plain map and white.
    f = bake_ao(slab(), resolution=16, samples=64, max_distance=D, quantity="thickness", margin=0, falloff=1.0)
    assert (DEPTH / D) ** 2 + 0.05 < f.ao[interior(f)].mean() < 0.95
