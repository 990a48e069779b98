"""Texel-centre geometry of a UV-mapped mesh, computed independently of core.geometry.raster.

Cycles bakes a texel only where a UV triangle covers the texel's centre (and jitters its samples
around that point inside that triangle); this module finds that triangle, the surface point, the
interpolated shading normal and the face normal at every texel centre, for the agreement checks.
"""

import numpy as np


def texel_centres(positions, triangles, uvs, normals, width, height):
    """Per texel (H, W): triangle index (-1 where no triangle covers the centre), world position (3),
    unit interpolated shading normal (3) and unit face normal (3), NaN where uncovered."""
    tri = np.full((height, width), -1, np.int64)
    pos = np.full((height, width, 3), np.nan)
    nrm = np.full((height, width, 3), np.nan)
    fn = np.full((height, width, 3), np.nan)
    P = positions[triangles]
    cross = np.cross(P[:, 1] - P[:, 0], P[:, 2] - P[:, 0])
    face = cross / np.maximum(np.linalg.norm(cross, axis=1, keepdims=True), 1e-300)
    uvp = np.asarray(uvs, np.float64) * [width, height]
    for k in range(len(triangles)):
        a, b, c = uvp[k]
        lo = np.floor(np.minimum(np.minimum(a, b), c) - 0.5).astype(int)
        hi = np.ceil(np.maximum(np.maximum(a, b), c)).astype(int)
        xs = np.arange(max(lo[0], 0), min(hi[0] + 1, width))
        ys = np.arange(max(lo[1], 0), min(hi[1] + 1, height))
        if not len(xs) or not len(ys):
            continue
        m = np.array([[b[0] - a[0], c[0] - a[0]], [b[1] - a[1], c[1] - a[1]]])
        det = np.linalg.det(m)
        if abs(det) < 1e-14:
            continue
        inv = np.linalg.inv(m)
        X, Y = np.meshgrid(xs + 0.5, ys + 0.5)
        l1 = inv[0, 0] * (X - a[0]) + inv[0, 1] * (Y - a[1])
        l2 = inv[1, 0] * (X - a[0]) + inv[1, 1] * (Y - a[1])
        l0 = 1.0 - l1 - l2
        inside = (l0 >= 0) & (l1 >= 0) & (l2 >= 0)
        if not inside.any():
            continue
        yy, xx = ys[np.nonzero(inside)[0]], xs[np.nonzero(inside)[1]]
        bc = np.stack([l0[inside], l1[inside], l2[inside]], 1)
        tri[yy, xx] = k
        pos[yy, xx] = bc @ P[k]
        n = bc @ (normals[k] if normals is not None else np.repeat(face[k][None], 3, 0))
        nrm[yy, xx] = n / np.maximum(np.linalg.norm(n, axis=1, keepdims=True), 1e-300)
        fn[yy, xx] = face[k]
    return tri, pos, nrm, fn


def normal_tilt_degrees(nrm, fn):
    """Angle between the shading normal and the face normal (oriented to its side), in degrees."""
    d = np.abs(np.sum(nrm * fn, axis=-1))
    return np.degrees(np.arccos(np.clip(d, -1.0, 1.0)))
