"""Warps from the unit square to shapes (inversion method), rejection samplers, and the sampler registry.

Every inversion warp is a triple in pbrt-v4's style: ``sample_X(u)`` maps points of [0,1)^d onto
the shape, ``X_pdf(points)`` is the density of those points with respect to the shape's measure
(length, area or solid angle, stated in each docstring) and is 0 outside the shape, and
``invert_X(points)`` maps back to u, so ``invert_X(sample_X(u)) == u``.

All functions are vectorised over a leading axis: u has shape (n, d), points (n, 1), (n, 2) or (n, 3).
"""

import math

import numpy as np

TWO_PI = 2.0 * math.pi
INV_PI = 1.0 / math.pi
INV_TWO_PI = 1.0 / TWO_PI
INV_FOUR_PI = 1.0 / (4.0 * math.pi)


def _as_points(u, d):
    u = np.asarray(u, dtype=np.float64)
    if u.ndim == 1 and d == 1:
        u = u[:, None]
    if u.ndim != 2 or u.shape[1] != d:
        raise ValueError(f"expected points of shape (n, {d}), got {u.shape}")
    return u


def _wrap_unit(x):
    """Angle fractions in [0, 1): atan2 returns (-pi, pi], the warps use phi in [0, 2 pi)."""
    x = np.mod(x, 1.0)
    return np.where(x >= 1.0, 0.0, x)  # mod can round -tiny up to exactly 1.0


# --- 1D: the linear ramp --------------------------------------------------------------------------


def sample_linear_ramp(u):
    """Inversion of P(y) = y^2 on [0, 1]: y = sqrt(u). Returns (n, 1)."""
    u = _as_points(u, 1)
    return np.sqrt(u)


def linear_ramp_pdf(y):
    """p(y) = 2y per unit length on [0, 1]; 0 outside."""
    y = _as_points(y, 1)[:, 0]
    return np.where((y >= 0.0) & (y <= 1.0), 2.0 * y, 0.0)


def invert_linear_ramp(y):
    """u = P(y) = y^2, the inverse of :func:`sample_linear_ramp`."""
    return _as_points(y, 1) ** 2


# --- disks -----------------------------------------------------------------------------------------


def sample_uniform_disk_polar(u):
    """Uniform unit disk by polar inversion: r = sqrt(u0), phi = 2 pi u1. Returns (n, 2)."""
    u = _as_points(u, 2)
    r = np.sqrt(u[:, 0])
    phi = TWO_PI * u[:, 1]
    return np.stack([r * np.cos(phi), r * np.sin(phi)], axis=1)


def uniform_disk_pdf(p):
    """p(x, y) = 1/pi per unit area inside the unit disk; 0 outside."""
    p = _as_points(p, 2)
    return np.where(np.einsum("ij,ij->i", p, p) <= 1.0, INV_PI, 0.0)


def invert_uniform_disk_polar(p):
    """u = (r^2, phi / 2 pi), the inverse of :func:`sample_uniform_disk_polar`."""
    p = _as_points(p, 2)
    r2 = np.einsum("ij,ij->i", p, p)
    return np.stack([r2, _wrap_unit(np.arctan2(p[:, 1], p[:, 0]) * INV_TWO_PI)], axis=1)


def concentric_disk_xy(u0, u1):
    """The concentric map on separate coordinate arrays (any shape): returns (x, y).

    Component arrays keep numpy's inner loops long; :func:`sample_uniform_disk_concentric` and the
    baker's ray generation both use it.
    """
    a = 2.0 * u0 - 1.0
    b = 2.0 * u1 - 1.0
    use_a = np.abs(a) > np.abs(b)
    with np.errstate(divide="ignore", invalid="ignore"):
        r = np.where(use_a, a, b)
        phi = np.where(use_a, (math.pi / 4.0) * (b / a), math.pi / 2.0 - (math.pi / 4.0) * (a / b))
    phi = np.where((a == 0.0) & (b == 0.0), 0.0, phi)
    return r * np.cos(phi), r * np.sin(phi)


def sample_uniform_disk_concentric(u):
    """Uniform unit disk by Shirley and Chiu's concentric map (low distortion, keeps strata compact).

    Squares around the origin of [-1, 1]^2 map to circles; each of the four wedges |a| > |b| and
    |b| >= |a| maps linearly in angle. Returns (n, 2).
    """
    u = _as_points(u, 2)
    return np.stack(concentric_disk_xy(u[:, 0], u[:, 1]), axis=1)


def invert_uniform_disk_concentric(p):
    """The inverse of :func:`sample_uniform_disk_concentric` (pbrt-v4's InvertUniformDiskConcentricSample)."""
    p = _as_points(p, 2)
    x, y = p[:, 0], p[:, 1]
    r = np.hypot(x, y)
    phi = np.arctan2(y, x)
    phi = np.where(phi < -math.pi / 4.0, phi + TWO_PI, phi)
    q = math.pi / 4.0
    w0 = phi < q
    w1 = ~w0 & (phi < 3.0 * q)
    w2 = ~w0 & ~w1 & (phi < 5.0 * q)
    # In each wedge one coordinate is +-r and the other follows linearly from the angle.
    a = np.select([w0, w1, w2], [r, -(phi - 2.0 * q) * r / q, -r], default=(phi - 6.0 * q) * r / q)
    b = np.select([w0, w1, w2], [phi * r / q, r, -(phi - 4.0 * q) * r / q], default=-r)
    return np.stack([(a + 1.0) * 0.5, (b + 1.0) * 0.5], axis=1)


# --- sphere and hemispheres (directions around +z) -------------------------------------------------


def _direction(z, phi):
    s = np.sqrt(np.maximum(0.0, 1.0 - z * z))
    return np.stack([s * np.cos(phi), s * np.sin(phi), z], axis=1)


def sample_uniform_sphere(u):
    """Uniform unit sphere: z = 1 - 2 u0, phi = 2 pi u1 (Archimedes: z is uniform). Returns (n, 3)."""
    u = _as_points(u, 2)
    return _direction(1.0 - 2.0 * u[:, 0], TWO_PI * u[:, 1])


def uniform_sphere_pdf(w):
    """p(w) = 1/(4 pi) per unit solid angle on the whole sphere."""
    w = _as_points(w, 3)
    return np.full(len(w), INV_FOUR_PI)


def invert_uniform_sphere(w):
    """u = ((1 - z) / 2, phi / 2 pi), the inverse of :func:`sample_uniform_sphere`."""
    w = _as_points(w, 3)
    return np.stack([(1.0 - w[:, 2]) * 0.5, _wrap_unit(np.arctan2(w[:, 1], w[:, 0]) * INV_TWO_PI)], axis=1)


def sample_uniform_hemisphere(u):
    """Uniform hemisphere around +z: cos(theta) = u0, phi = 2 pi u1. Returns (n, 3)."""
    u = _as_points(u, 2)
    return _direction(u[:, 0], TWO_PI * u[:, 1])


def uniform_hemisphere_pdf(w):
    """p(w) = 1/(2 pi) per unit solid angle for z > 0; 0 below the horizon."""
    w = _as_points(w, 3)
    return np.where(w[:, 2] > 0.0, INV_TWO_PI, 0.0)


def invert_uniform_hemisphere(w):
    """u = (z, phi / 2 pi), the inverse of :func:`sample_uniform_hemisphere`."""
    w = _as_points(w, 3)
    return np.stack([w[:, 2], _wrap_unit(np.arctan2(w[:, 1], w[:, 0]) * INV_TWO_PI)], axis=1)


def sample_cosine_hemisphere(u):
    """Cosine-weighted hemisphere around +z by Malley's method.

    A uniform point on the disk (concentric map) lifted onto the hemisphere above it has density
    cos(theta)/pi in solid angle, because the projected solid angle is cos(theta) dw. Returns (n, 3).
    """
    d = sample_uniform_disk_concentric(u)
    z = np.sqrt(np.maximum(0.0, 1.0 - np.einsum("ij,ij->i", d, d)))
    return np.concatenate([d, z[:, None]], axis=1)


def cosine_hemisphere_pdf(w):
    """p(w) = cos(theta)/pi per unit solid angle for z > 0; 0 below the horizon."""
    w = _as_points(w, 3)
    return np.where(w[:, 2] > 0.0, w[:, 2] * INV_PI, 0.0)


def invert_cosine_hemisphere(w):
    """The inverse of :func:`sample_cosine_hemisphere`: project to the disk, then invert the concentric map."""
    w = _as_points(w, 3)
    return invert_uniform_disk_concentric(w[:, :2])


def cosine_hemisphere_polar_xyz(u0, u1):
    """Malley's method with the polar disk map, on component arrays (any shape): returns (x, y, z).

    r = sqrt(u0), phi = 2 pi u1 on the disk, lifted to z = sqrt(1 - u0): density cos(theta)/pi.
    sin^2(theta) = u0, so u0 orders directions by their angle from the normal and u1 by azimuth: a
    rotation about the normal is a shift of u1. This is the map the baker uses (core.engine.patterns).
    """
    r = np.sqrt(u0)
    phi = TWO_PI * u1
    return r * np.cos(phi), r * np.sin(phi), np.sqrt(np.maximum(0.0, 1.0 - u0))


def sample_cosine_hemisphere_polar(u):
    """Cosine-weighted hemisphere around +z by Malley's method with the polar disk map. Returns (n, 3)."""
    u = _as_points(u, 2)
    return np.stack(cosine_hemisphere_polar_xyz(u[:, 0], u[:, 1]), axis=1)


def invert_cosine_hemisphere_polar(w):
    """u = (x^2 + y^2, phi / 2 pi), the inverse of :func:`sample_cosine_hemisphere_polar`."""
    w = _as_points(w, 3)
    return np.stack([w[:, 0] ** 2 + w[:, 1] ** 2, _wrap_unit(np.arctan2(w[:, 1], w[:, 0]) * INV_TWO_PI)], axis=1)


def cosine_sphere_point(x, y, z):
    """The point v of the unit sphere with normalize(n + v) = (x, y, z), for a direction (x, y, z)
    given in the frame of the normal n (z along n); component arrays in, (vx, vy, vz) out.

    A sphere of radius 1 centred at n passes through the surface point, and the direction from the
    point to a uniform point n + v of that sphere has density cos(theta)/pi (inscribed angle: the
    direction's theta is half the angle between v and n, so sin^2(theta) = (1 - v.n) / 2). Hence
    v = (2 z x, 2 z y, 2 z^2 - 1), and for v drawn by :func:`sample_uniform_sphere` with a pole
    along n, normalize(n + v) is exactly :func:`sample_cosine_hemisphere_polar` of the same u. The
    baker uses this form where the shading normal changes from sample to sample: it needs no frame
    at each sample, only the normal.
    """
    return 2.0 * z * x, 2.0 * z * y, 2.0 * z * z - 1.0


def uniform_hemisphere_xyz(u0, u1):
    """:func:`sample_uniform_hemisphere` on component arrays: cos(theta) = u0, phi = 2 pi u1."""
    s = np.sqrt(np.maximum(0.0, 1.0 - u0 * u0))
    phi = TWO_PI * u1
    return s * np.cos(phi), s * np.sin(phi), u0


def sample_uniform_hemisphere_by_flip(u, n=(0.0, 0.0, 1.0)):
    """Uniform hemisphere around ``n``: a uniform sphere direction, negated when it points below.

    The sphere is symmetric under w -> -w, so folding its lower half onto the upper one doubles the
    density there: 1/(2 pi). The baker uses it with per-sample normals (no frame needed). Returns (n, 3).
    """
    w = sample_uniform_sphere(u)
    n = np.asarray(n, dtype=np.float64)
    return np.where((w @ n < 0.0)[:, None], -w, w)


# --- triangles ---------------------------------------------------------------------------------------


def square_to_triangle(a, b, out=None):
    """Heitz's low-distortion map from the square to the triangle, on component arrays of any scale.

    Heitz 2019, "A Low-Distortion Map Between Triangle and Square" (pbrt-v4's SampleUniformTriangle):
    if a < b then (a / 2, b - a / 2) else (a - b / 2, b / 2), which is (a - m, b - m) with m half the
    smaller coordinate. Returns the barycentric weights (b0, b1) of corners 0 and 1 (b2 = s - b0 - b1
    at scale s). Homogeneous of degree 1, so it also works on coordinates scaled by 2^32. ``out``:
    a pair of arrays to write (b0, b1) into (may be a and b themselves).
    """
    m = np.minimum(a, b)
    m *= 0.5
    if out is None:
        return a - m, b - m
    np.subtract(a, m, out=out[0])
    np.subtract(b, m, out=out[1])
    return out


def sample_uniform_triangle(u):
    """Uniform point of the triangle {b0, b1 >= 0, b0 + b1 <= 1} as barycentrics (b0, b1). Returns (n, 2)."""
    u = _as_points(u, 2)
    return np.stack(square_to_triangle(u[:, 0], u[:, 1]), axis=1)


def uniform_triangle_pdf(b):
    """p(b0, b1) = 2 per unit area of the (b0, b1) plane inside the triangle; 0 outside."""
    b = _as_points(b, 2)
    inside = (b[:, 0] >= 0.0) & (b[:, 1] >= 0.0) & (b[:, 0] + b[:, 1] <= 1.0)
    return np.where(inside, 2.0, 0.0)


def invert_uniform_triangle(b):
    """The inverse of :func:`sample_uniform_triangle`: (2 b0, b0 + b1) if b0 < b1, else (b0 + b1, 2 b1)."""
    b = _as_points(b, 2)
    first = b[:, 0] < b[:, 1]
    s = b[:, 0] + b[:, 1]
    return np.stack([np.where(first, 2.0 * b[:, 0], s), np.where(first, s, 2.0 * b[:, 1])], axis=1)


# --- orienting around a normal ---------------------------------------------------------------------


def orthonormal_basis(n):
    """Two tangents (s, t) such that (s, t, n) is a right-handed orthonormal frame: s x t = n.

    Duff et al. 2017, "Building an Orthonormal Basis, Revisited": branch-free, exact at n = +-z
    and accurate everywhere. No tangent field on the sphere is continuous everywhere (the hairy-ball
    theorem); this one is smooth except where n.z changes sign, and the choice of s, t never
    changes what a rotation-invariant integral such as AO estimates.

    Parameters
    ----------
    n : (m, 3) or (3,) array of unit normals.

    Returns
    -------
    s, t : arrays of the same shape as n.
    """
    n = np.asarray(n, dtype=np.float64)
    sx, sy, sz, tx, ty, tz = basis_components(n[..., 0], n[..., 1], n[..., 2])
    return np.stack([sx, sy, sz], axis=-1), np.stack([tx, ty, tz], axis=-1)


def basis_components(x, y, z):
    """:func:`orthonormal_basis` on separate component arrays: returns (sx, sy, sz, tx, ty, tz)."""
    sign = np.copysign(1.0, z)
    a = -1.0 / (sign + z)
    b = x * y * a
    return 1.0 + sign * x * x * a, sign * b, -sign * x, b, sign + y * y * a, -y


def rotate_tangents(s, t, cos_a, sin_a):
    """Tangents (s, t) turned by an angle a about their normal: (cos a s + sin a t, cos a t - sin a s).

    A direction with azimuth phi in the turned frame has azimuth phi + a in the original one, so
    turning the frame is a shift of the polar map's u1 by a / (2 pi). Arrays broadcast together.
    """
    return cos_a * s + sin_a * t, cos_a * t - sin_a * s


def to_world(local, n):
    """Rotate directions given in the frame of n (z along n) into world space."""
    local = np.asarray(local, dtype=np.float64)
    s, t = orthonormal_basis(n)
    n = np.asarray(n, dtype=np.float64)
    return local[..., 0:1] * s + local[..., 1:2] * t + local[..., 2:3] * n


def to_local(world, n):
    """Coordinates of world-space directions in the frame of n (the inverse of :func:`to_world`)."""
    world = np.asarray(world, dtype=np.float64)
    s, t = orthonormal_basis(n)
    n = np.broadcast_to(np.asarray(n, dtype=np.float64), world.shape)
    dot = lambda a, b: np.einsum("...i,...i->...", a, np.broadcast_to(b, a.shape))  # noqa: E731
    return np.stack([dot(world, s), dot(world, t), dot(world, n)], axis=-1)


# --- piecewise-constant distributions (tables) ------------------------------------------------------


class PiecewiseConstant1D:
    """A 1D density proportional to a table of non-negative values on equal bins of [a, b].

    Sampled by inverting its CDF (pbrt's PiecewiseConstant1D). Bins of value 0 are never sampled.
    """

    def __init__(self, values, a=0.0, b=1.0):
        f = np.asarray(values, dtype=np.float64).ravel()
        if f.size == 0 or not np.all(np.isfinite(f)) or np.any(f < 0):
            raise ValueError("PiecewiseConstant1D needs a non-empty table of finite, non-negative values")
        if not b > a:
            raise ValueError(f"PiecewiseConstant1D needs a < b, got [{a}, {b}]")
        total = f.sum()
        if total <= 0:
            raise ValueError("PiecewiseConstant1D: every table value is zero, there is nothing to sample")
        self.values, self.a, self.b, self.n = f, float(a), float(b), f.size
        self.integral = total * (self.b - self.a) / self.n  # integral of the table as a function on [a, b]
        self.cdf = np.concatenate([[0.0], np.cumsum(f) / total])
        self.cdf[-1] = 1.0

    def sample(self, u):
        """x in [a, b) with density :meth:`pdf`. Returns (n, 1)."""
        u = _as_points(u, 1)[:, 0]
        o = np.clip(np.searchsorted(self.cdf, u, side="right") - 1, 0, self.n - 1)
        width = self.cdf[o + 1] - self.cdf[o]
        du = np.where(width > 0, (u - self.cdf[o]) / np.where(width > 0, width, 1.0), 0.0)
        x = self.a + (o + du) * (self.b - self.a) / self.n
        return x[:, None]

    def pdf(self, x):
        """Density per unit length on [a, b]: values[bin] / integral; 0 outside."""
        x = _as_points(x, 1)[:, 0]
        inside = (x >= self.a) & (x <= self.b)
        o = np.clip(((x - self.a) / (self.b - self.a) * self.n).astype(np.int64), 0, self.n - 1)
        return np.where(inside, self.values[o] / self.integral, 0.0)

    def invert(self, x):
        """u = CDF(x), the inverse of :meth:`sample`."""
        x = _as_points(x, 1)[:, 0]
        t = (x - self.a) / (self.b - self.a) * self.n
        o = np.clip(np.floor(t).astype(np.int64), 0, self.n - 1)
        return (self.cdf[o] + (t - o) * (self.cdf[o + 1] - self.cdf[o]))[:, None]


class PiecewiseConstant2D:
    """A density on the unit square proportional to a table (rows along y, columns along x).

    Sampled as the lecture's last slide teaches: y from the marginal p(y) = integral of p(x, y) dx,
    then x from the conditional p(x | y) = p(x, y) / p(y). u[:, 1] drives the marginal and u[:, 0]
    the conditional, so each is a 1D inversion.
    """

    def __init__(self, table):
        f = np.asarray(table, dtype=np.float64)
        if f.ndim != 2 or f.size == 0 or not np.all(np.isfinite(f)) or np.any(f < 0):
            raise ValueError("PiecewiseConstant2D needs a non-empty 2D table of finite, non-negative values")
        self.table = f
        self.ny, self.nx = f.shape
        row_sums = f.sum(axis=1)
        self.marginal = PiecewiseConstant1D(row_sums)  # raises if the whole table is zero
        self.integral = f.sum() / f.size  # integral over the unit square
        safe = np.where(row_sums > 0, row_sums, 1.0)[:, None]
        cond = np.cumsum(np.where(row_sums[:, None] > 0, f, 1.0) / np.where(row_sums[:, None] > 0, safe, self.nx), axis=1)
        cond = np.concatenate([np.zeros((self.ny, 1)), cond], axis=1)
        cond[:, -1] = 1.0
        self.conditional_cdf = cond
        # Row k's CDF shifted by k is still increasing across rows, so one searchsorted serves all rows.
        self._flat = (cond + np.arange(self.ny)[:, None]).ravel()

    def _rows(self, y):
        return np.clip((y * self.ny).astype(np.int64), 0, self.ny - 1)

    def sample(self, u):
        """(x, y) in [0, 1)^2 with density :meth:`pdf`. Returns (n, 2)."""
        u = _as_points(u, 2)
        y = self.marginal.sample(u[:, 1:2])[:, 0]
        row = self._rows(y)
        k = np.searchsorted(self._flat, row + u[:, 0], side="right") - 1 - row * (self.nx + 1)
        o = np.clip(k, 0, self.nx - 1)
        lo = self.conditional_cdf[row, o]
        width = self.conditional_cdf[row, o + 1] - lo
        du = np.where(width > 0, (u[:, 0] - lo) / np.where(width > 0, width, 1.0), 0.0)
        return np.stack([(o + du) / self.nx, y], axis=1)

    def pdf(self, p):
        """Density per unit area on the unit square: table[row, col] / integral; 0 outside."""
        p = _as_points(p, 2)
        inside = np.all((p >= 0.0) & (p <= 1.0), axis=1)
        col = np.clip((p[:, 0] * self.nx).astype(np.int64), 0, self.nx - 1)
        return np.where(inside, self.table[self._rows(p[:, 1]), col] / self.integral, 0.0)

    def invert(self, p):
        """u such that sample(u) == p: the conditional CDF at x, the marginal CDF at y."""
        p = _as_points(p, 2)
        row = self._rows(p[:, 1])
        t = p[:, 0] * self.nx
        o = np.clip(np.floor(t).astype(np.int64), 0, self.nx - 1)
        lo = self.conditional_cdf[row, o]
        u0 = lo + (t - o) * (self.conditional_cdf[row, o + 1] - lo)
        return np.stack([u0, self.marginal.invert(p[:, 1:2])[:, 0]], axis=1)


# --- rejection samplers, as the lecture writes them ------------------------------------------------


class RejectionSampler:
    """Draw points uniformly in the cube [-1, 1]^d and keep those the shape's test accepts.

    The lecture's do-while loops, vectorised: candidates are drawn in batches sized from the
    expected acceptance rate until n are accepted, in the order the loop would have produced them.
    ``acceptance_rate`` is the measured fraction of candidates kept over every draw so far;
    ``expected_acceptance`` the exact value (volume of the accepted region / volume of the cube).
    """

    dims_in = 2
    expected_acceptance = 1.0

    def __init__(self):
        self.trials = 0
        self.accepted = 0

    @property
    def acceptance_rate(self):
        return self.accepted / self.trials if self.trials else float("nan")

    def _accept(self, v):
        return np.einsum("ij,ij->i", v, v) <= 1.0

    def _finish(self, v):
        return v

    def draw(self, n, rng=None):
        rng = np.random.default_rng(rng)
        out, have = [], 0
        while have < n:
            m = max(16, int((n - have) / self.expected_acceptance * 1.1) + 16)
            v = 1.0 - 2.0 * rng.random((m, self.dims_in))
            ok = self._accept(v)
            idx = np.flatnonzero(ok)[: n - have]
            # Count only the candidates the sequential loop would have looked at.
            self.trials += (idx[-1] + 1) if have + ok.sum() >= n and len(idx) else m
            self.accepted += len(idx)
            out.append(v[idx])
            have += len(idx)
        v = np.concatenate(out) if out else np.zeros((0, self.dims_in))
        return self._finish(v)


class RejectionDisk(RejectionSampler):
    """Uniform unit disk: reject points of the square outside the circle. Acceptance pi/4."""

    dims_in = 2
    expected_acceptance = math.pi / 4.0

    def pdf(self, p):
        return uniform_disk_pdf(p)


class RejectionSphere(RejectionSampler):
    """Uniform sphere: reject points of the cube outside the ball, then project. Acceptance pi/6.

    The origin itself (length 0, probability zero but possible in floating point) is rejected too,
    since it has no direction.
    """

    dims_in = 3
    expected_acceptance = math.pi / 6.0

    def _accept(self, v):
        r2 = np.einsum("ij,ij->i", v, v)
        return (r2 <= 1.0) & (r2 > 0.0)

    def _finish(self, v):
        return v / np.linalg.norm(v, axis=1, keepdims=True)

    def pdf(self, w):
        return uniform_sphere_pdf(w)


class RejectionHemisphere(RejectionSphere):
    """Uniform hemisphere around ``normal`` by rejection, in the lecture's three variants.

    - 'reject_z': reject |v| > 1 or v.z < 0 (the hemisphere around +z). Acceptance pi/12.
    - 'reject_normal': reject |v| > 1 or dot(v, n) < 0, for any normal. Acceptance pi/12.
    - 'flip': reject |v| > 1 only, then v = -v where dot(v, n) < 0. Acceptance pi/6: twice as
      efficient, and still uniform because the ball is symmetric under v -> -v.
    All project onto the unit sphere.
    """

    def __init__(self, variant="reject_z", normal=(0.0, 0.0, 1.0)):
        super().__init__()
        if variant not in ("reject_z", "reject_normal", "flip"):
            raise ValueError(f"unknown rejection hemisphere variant {variant!r}")
        n = np.asarray(normal, dtype=np.float64)
        self.variant = variant
        self.normal = n / np.linalg.norm(n)
        if variant == "reject_z":
            self.normal = np.array([0.0, 0.0, 1.0])
        self.expected_acceptance = math.pi / 6.0 if variant == "flip" else math.pi / 12.0

    def _accept(self, v):
        ok = super()._accept(v)
        if self.variant == "reject_z":
            return ok & (v[:, 2] >= 0.0)
        if self.variant == "reject_normal":
            return ok & (v @ self.normal >= 0.0)
        return ok

    def _finish(self, v):
        if self.variant == "flip":
            v = np.where((v @ self.normal < 0.0)[:, None], -v, v)
        return super()._finish(v)

    def pdf(self, w):
        w = _as_points(w, 3)
        return np.where(w @ self.normal > 0.0, INV_TWO_PI, 0.0)


# --- the registry: one interface for every sampler, so one generic test reaches them all -------------


class Sampler:
    """A named sampler: ``draw(n, rng) -> (n, d)``, ``pdf(points) -> (n,)``, ``domain``.

    Inversion warps also carry ``sample(u)`` and ``inverse(points)``; hemispheres around a normal
    other than +z carry ``normal``; rejection samplers expose their ``rejection`` object, whose
    ``acceptance_rate`` is measured.
    """

    def __init__(self, name, domain, dim, pdf, sample=None, inverse=None, draw=None, normal=None,
                 rejection=None, u_dim=None):
        self.name, self.domain, self.dim = name, domain, dim
        self.pdf = pdf
        self.sample, self.inverse = sample, inverse
        self.u_dim = u_dim if u_dim is not None else (dim if domain in ("interval", "square", "disk") else 2)
        self._draw = draw
        self.rejection = rejection
        if normal is not None:
            self.normal = np.asarray(normal, dtype=np.float64) / np.linalg.norm(normal)

    def draw(self, n, rng=None):
        rng = np.random.default_rng(rng)
        if self._draw is not None:
            return self._draw(n, rng)
        return self.sample(rng.random((n, self.u_dim)))

    def __repr__(self):
        return f"Sampler({self.name!r}, domain={self.domain!r})"


def _oriented(name, sample, pdf, inverse, normal):
    """A +z hemisphere warp turned into the frame of ``normal``."""
    n = np.asarray(normal, dtype=np.float64) / np.linalg.norm(normal)
    return Sampler(
        name, "hemisphere", 3,
        pdf=lambda w: pdf(to_local(_as_points(w, 3), n)),
        sample=lambda u: to_world(sample(u), n),
        inverse=lambda w: inverse(to_local(_as_points(w, 3), n)),
        normal=n,
    )


#: A fixed, deliberately lopsided table for the piecewise-constant examples (zeros included).
EXAMPLE_TABLE_1D = np.array([1.0, 3.0, 0.0, 2.0, 5.0, 0.5, 4.0, 1.0, 0.0, 2.5, 3.5, 1.5])
EXAMPLE_TABLE_2D = np.array([
    [1.0, 2.0, 0.0, 4.0, 1.0, 0.5, 2.0, 3.0],
    [0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0],
    [5.0, 1.0, 1.0, 2.0, 0.2, 3.0, 1.0, 0.0],
    [2.0, 2.0, 2.0, 2.0, 2.0, 2.0, 2.0, 2.0],
    [0.3, 4.0, 6.0, 1.0, 0.0, 1.0, 2.0, 7.0],
    [1.0, 0.0, 1.0, 0.0, 1.0, 0.0, 1.0, 0.0],
])
#: An oblique normal for the samplers oriented around an arbitrary axis.
EXAMPLE_NORMAL = np.array([0.48, -0.6, -0.64])


def _normalized(v):
    return v / np.linalg.norm(v, axis=-1, keepdims=True)


def _rejection_entry(name, domain, dim, make):
    r = make()
    return Sampler(name, domain, dim, pdf=r.pdf, draw=r.draw, rejection=r,
                   normal=getattr(r, "normal", None) if domain == "hemisphere" else None)


def _build_registry():
    pc1 = PiecewiseConstant1D(EXAMPLE_TABLE_1D)
    pc2 = PiecewiseConstant2D(EXAMPLE_TABLE_2D)
    entries = [
        Sampler("linear_ramp", "interval", 1, linear_ramp_pdf, sample_linear_ramp, invert_linear_ramp),
        Sampler("piecewise_constant_1d", "interval", 1, pc1.pdf, pc1.sample, pc1.invert),
        Sampler("piecewise_constant_2d", "square", 2, pc2.pdf, pc2.sample, pc2.invert),
        Sampler("disk_polar", "disk", 2, uniform_disk_pdf, sample_uniform_disk_polar, invert_uniform_disk_polar),
        Sampler("disk_concentric", "disk", 2, uniform_disk_pdf, sample_uniform_disk_concentric,
                invert_uniform_disk_concentric),
        Sampler("sphere_uniform", "sphere", 3, uniform_sphere_pdf, sample_uniform_sphere, invert_uniform_sphere),
        Sampler("hemisphere_uniform", "hemisphere", 3, uniform_hemisphere_pdf, sample_uniform_hemisphere,
                invert_uniform_hemisphere),
        Sampler("hemisphere_cosine", "hemisphere", 3, cosine_hemisphere_pdf, sample_cosine_hemisphere,
                invert_cosine_hemisphere),
        Sampler("hemisphere_cosine_polar", "hemisphere", 3, cosine_hemisphere_pdf, sample_cosine_hemisphere_polar,
                invert_cosine_hemisphere_polar),
        Sampler("hemisphere_cosine_sphere", "hemisphere", 3,
                lambda w: cosine_hemisphere_pdf(to_local(_as_points(w, 3), EXAMPLE_NORMAL / np.linalg.norm(EXAMPLE_NORMAL))),
                lambda u: _normalized(EXAMPLE_NORMAL / np.linalg.norm(EXAMPLE_NORMAL)
                                      + to_world(sample_uniform_sphere(u), EXAMPLE_NORMAL / np.linalg.norm(EXAMPLE_NORMAL))),
                normal=EXAMPLE_NORMAL),
        Sampler("hemisphere_uniform_flip", "hemisphere", 3,
                lambda w: uniform_hemisphere_pdf(to_local(_as_points(w, 3), EXAMPLE_NORMAL / np.linalg.norm(EXAMPLE_NORMAL))),
                lambda u: sample_uniform_hemisphere_by_flip(u, EXAMPLE_NORMAL / np.linalg.norm(EXAMPLE_NORMAL)),
                normal=EXAMPLE_NORMAL),
        Sampler("triangle_heitz", "triangle", 2, uniform_triangle_pdf, sample_uniform_triangle, invert_uniform_triangle),
        _oriented("hemisphere_uniform_oriented", sample_uniform_hemisphere, uniform_hemisphere_pdf,
                  invert_uniform_hemisphere, EXAMPLE_NORMAL),
        _oriented("hemisphere_cosine_oriented", sample_cosine_hemisphere, cosine_hemisphere_pdf,
                  invert_cosine_hemisphere, EXAMPLE_NORMAL),
        _rejection_entry("disk_rejection", "disk", 2, RejectionDisk),
        _rejection_entry("sphere_rejection", "sphere", 3, RejectionSphere),
        _rejection_entry("hemisphere_rejection_z", "hemisphere", 3, lambda: RejectionHemisphere("reject_z")),
        _rejection_entry("hemisphere_rejection_normal", "hemisphere", 3,
                         lambda: RejectionHemisphere("reject_normal", EXAMPLE_NORMAL)),
        _rejection_entry("hemisphere_rejection_flip", "hemisphere", 3,
                         lambda: RejectionHemisphere("flip", EXAMPLE_NORMAL)),
    ]
    return {s.name: s for s in entries}


#: name -> :class:`Sampler`, every sampler of this module (inversion and rejection).
REGISTRY = _build_registry()
