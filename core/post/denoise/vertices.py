"""The denoiser on values at face corners: the sample points joined by the mesh's edges in place of an image window."""

import numpy as np

from .filter import DenoiseInfo, NORMAL_SHARPNESS, RANGE_FLAT, RANGE_SIGMAS


#: Candidate bandwidths of the vertex filter, in lengths of the edges around each sample point.
VERTEX_BANDWIDTHS = (1.0, 1.4, 2.0)


def _two_ring(a, b, n):
    """The pairs (sorted by first, then second; both directions; no self pair) of points joined by
    one or two of the pairs (a, b) (both directions already, sorted by a)."""
    count = np.bincount(a, minlength=n)
    start = np.concatenate([[0], np.cumsum(count)])
    reps = count[b]
    first = np.repeat(a, reps)
    offs = np.arange(int(reps.sum())) - np.repeat(np.cumsum(reps) - reps, reps)
    third = b[np.repeat(start[b], reps) + offs]
    aa, cc = np.concatenate([a, first]), np.concatenate([b, third])
    keep = aa != cc
    pair = np.unique(np.stack([aa[keep], cc[keep]], axis=1), axis=0)
    return pair[:, 0], pair[:, 1]


def denoise_vertices(mesh, ao, stderr, unit, corners=None, *, bandwidths=VERTEX_BANDWIDTHS,
                     normal_sharpness=NORMAL_SHARPNESS, range_sigmas=RANGE_SIGMAS, range_flat=RANGE_FLAT,
                     use_error=True, use_bias=True):
    """Denoise AO baked at face corners (:func:`core.bake_vertex_ao`) over the mesh's vertex
    neighbours: the same filter as :func:`denoise`, with the sample points joined by the mesh's edges
    (up to two edges away) in place of an image window.

    Parameters
    ----------
    mesh : the baked core.Mesh; ao, stderr, unit : per corner, as :class:`core.VertexBakeResult`
        holds them; corners : the (C, 2) corners baked (None: every triangle corner).
    bandwidths : candidate widths in lengths of the edges around each point (their mean).
    The others as :func:`denoise`.

    Returns
    -------
    (ao, stderr, info) per corner (float32), info a :class:`DenoiseInfo` per corner.
    """
    from ...geometry.corners import all_corners, unit_pairs

    corners = all_corners(mesh) if corners is None else np.asarray(corners, np.int64)
    unit = np.asarray(unit, np.int64)
    n = int(unit.max()) + 1 if len(unit) else 0
    _, first = np.unique(unit, return_index=True)
    tri, k = corners[first, 0], corners[first, 1]
    vert = mesh.triangles[tri, k]
    p = mesh.positions[vert]
    nrm = mesh.normals[tri, k]
    y = np.asarray(ao, np.float64)[first]
    var = np.asarray(stderr, np.float64)[first] ** 2
    a1, b1 = unit_pairs(mesh, vert)
    d1 = np.linalg.norm(p[a1] - p[b1], axis=1)
    apart = d1 > 0
    length = np.bincount(a1[apart], d1[apart], minlength=n) / np.maximum(np.bincount(a1[apart], minlength=n), 1)
    length = np.where(length > 0, length, 1.0)
    beta = float(normal_sharpness)

    def geometry(a, b):
        d2 = np.sum((p[a] - p[b]) ** 2, axis=1) / (length[a] * length[b])
        return d2, np.sum(nrm[a] * nrm[b], axis=1)

    def sums(a, w, x):
        return np.bincount(a, w * x, minlength=n)

    a2, b2 = _two_ring(a1, b1, n)
    exact = var == 0
    if use_error and len(a2):
        # Trusted zeros, as _trusted_zeros: the bake pools a point's error over its vertex's 1-ring
        # only, so all 16 samples of 7 points may agree where the AO is 0.97; a zero is trusted
        # where the 2-ring agrees too.
        nz = var[b2] > 0
        cnt = np.bincount(a2[nz], minlength=n)
        mean = np.bincount(a2[nz], var[b2][nz], minlength=n) / np.maximum(cnt, 1)
        var = np.where(exact & (cnt > 0), mean, var)
        exact &= var == 0
    # Pilot: geometry only, the 1-ring, the narrowest bandwidth.
    d2, dot = geometry(a1, b1)
    g = np.exp(-(d2 * (0.5 / bandwidths[0] ** 2) + beta * (1.0 - dot)))
    Wg = 1.0 + np.bincount(a1, g, minlength=n)
    G = (y + sums(a1, g, y[b1])) / Wg
    vG = (var + sums(a1, g * g, var[b1])) / Wg ** 2
    # Candidates over the 2-ring.
    d2, dot = geometry(a2, b2)
    rng = np.maximum((G[a2] - G[b2]) ** 2 / (2 * range_sigmas ** 2 * (vG[a2] + vG[b2]) + 1e-12) - range_flat, 0.0)
    base = beta * (1.0 - dot) + rng
    F, V, B = [], [], []
    for h in bandwidths:
        w = np.exp(-(d2 * (0.5 / h ** 2) + base))
        W = 1.0 + np.bincount(a2, w, minlength=n)
        f = (y + sums(a2, w, y[b2])) / W
        F.append(f)
        V.append((var + sums(a2, w * w, var[b2])) / W ** 2)
        B.append((f + sums(a2, w, f[b2])) / W - f if use_bias else np.zeros(n))
    if use_error:
        best, choice = var.copy(), np.zeros(n, np.int8)
        for i in range(len(bandwidths)):
            m = V[i] + B[i] ** 2
            take = m < best
            best = np.where(take, m, best)
            choice[take] = i + 1
        choice[exact] = 0
    else:
        choice = np.full(n, len(bandwidths), np.int8)
    out, vo, bo = y.copy(), var.copy(), np.zeros(n)
    for i in range(len(bandwidths)):
        take = choice == i + 1
        out[take], vo[take], bo[take] = F[i][take], V[i][take], B[i][take]
    se = np.sqrt(vo + bo * bo)
    info = DenoiseInfo(choice=choice[unit], variance=vo[unit].astype(np.float32), bias=bo[unit].astype(np.float32),
                       bandwidths=tuple(float(b) for b in bandwidths))
    return np.clip(out, 0.0, 1.0)[unit].astype(np.float32), se[unit].astype(np.float32), info


__all__ = ["VERTEX_BANDWIDTHS", "denoise_vertices"]
