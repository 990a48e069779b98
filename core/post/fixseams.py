"""Fix Seams: the least-squares pass after an image bake that makes the bilinear lookups on both sides
of every smooth UV seam agree (:mod:`core.geometry.seams` finds the seams and their lookups).

Lightmappers fix seams this way (Iwanicki, "Lighting technology of The Last of Us", SIGGRAPH 2013; the
seamoptimizer library): the texels a seam's lookups read are solved for, so that the lookups agree
in the least-squares sense while each texel stays close to its value. Here each covered texel is
held to its estimate in proportion to its standard error, margin texels (no estimate of their own)
nearly not at all, exact texels (no error) and other targets' texels not moved; numpy alone
(conjugate gradients, a fixed order), so the result is the same bits whatever the threads or
processes that baked the image.
"""

import math
from dataclasses import dataclass

import numpy as np

#: Weight of the squared mismatch per texel of seam length, in units of the squared error of a
#: typical texel (the median standard error of the covered texels the fix may change).
SEAM_WEIGHT = 100.0
#: Weight that keeps a margin (or empty) texel near its value, in the same units: small, so that the
#: margin takes the seam's correction first (it holds no estimate of its own).
MARGIN_WEIGHT = 1e-2
#: Conjugate gradients stop when the preconditioned residual has fallen by this factor, or after
#: MAX_ITERATIONS.
TOLERANCE = 1e-6
MAX_ITERATIONS = 2000
#: Solves at most, each holding the texels the last one took past the value range at its bound.
BOUND_ROUNDS = 4


def _dot(a, b):
    # A running sum (np.cumsum adds in order): the same bits for any BLAS thread count and numpy's
    # reduction loops (pairwise, SIMD-unrolled differently by numpy 1.26 and 2.x).
    p = a * b
    return float(np.cumsum(p)[-1]) if len(p) else 0.0


@dataclass
class SeamFix:
    """What :func:`fix_seams` did: texels (flat indices it changed the values of), iterations,
    residual (the preconditioned residual's norm over the initial one), before and after (the
    mismatch of the lookups at smooth seams, those it makes agree), unknowns (texels it solved
    for), rounds (solves, each holding texels at a bound), points (the smooth seams' points)."""

    texels: np.ndarray
    iterations: int
    residual: float
    before: float
    after: float
    unknowns: int
    rounds: int = 1
    points: int = 0


class _System:
    """The normal equations of the fix over its unknowns (see :func:`fix_seams`), in units of s_ref^2:
    A x = b, A = D + C^T diag(lam) C, applied without forming A. C is kept as its eight columns of
    (K,) weights and unknown indices (contiguous; each product a sum of eight gathers, each
    transpose eight bincounts added in order), so no (K, 8) temporary is made per iteration."""

    def __init__(self, flat_v, flat_s, flat_m, lookups, owner, seam_weight, margin_weight, pinned=None):
        touched, pos = np.unique(lookups.index.T, return_inverse=True)  # pos: (8, K), column by column
        it = np.int32 if len(touched) < 2 ** 31 else np.int64
        pos = pos.reshape(8, -1).astype(it)
        y = flat_v[touched].astype(np.float64)
        s = flat_s[touched].astype(np.float64)
        covered = flat_m[touched]
        free = ~(covered & (s <= 0))
        if owner is not None:
            own = np.asarray(owner).reshape(-1)[touched]
            for j in range(8):
                other = (own[pos[j]] >= 0) & (own[pos[j]] != lookups.target)
                free[pos[j][other]] = False
        self.solvable = free.copy()  # before any texel is pinned at a bound
        if pinned is not None:  # (positions among the touched texels, the values they are held at)
            free[pinned[0]] = False
            y[pinned[0]] = pinned[1]
        self.touched, self.free = touched, free
        self.n = n = int(free.sum())
        fi = (np.cumsum(free) - 1).astype(it)  # index among the unknowns
        cov_free = covered & free
        self.s_ref = s_ref = float(np.median(s[cov_free])) if cov_free.any() else 1.0
        self.covered = covered[free]
        self.s = s[free]
        self.d = np.where(covered, (s_ref / np.where(s > 0, s, s_ref)) ** 2, margin_weight)[free]
        self.lam = seam_weight * lookups.length
        self.c = np.empty((8, len(self.lam)))
        self.col = np.empty((8, len(self.lam)), it)
        g = np.zeros(len(self.lam))  # the held texels' part of each difference
        for j in range(8):
            var = free[pos[j]]
            w = lookups.weight[:, j]
            self.c[j] = np.where(var, w, 0.0)
            self.col[j] = np.where(var, fi[pos[j]], 0)
            g += np.where(var, 0.0, w) * y[pos[j]]
        del pos
        self.y = y[free]
        self.b = self.d * self.y - self.ctr(self.lam * g)
        self.diag = self.d.copy()
        for j in range(8):
            self.diag += np.bincount(self.col[j], weights=self.lam * self.c[j] * self.c[j], minlength=n)

    def cx(self, x):
        out = self.c[0] * x[self.col[0]]
        for j in range(1, 8):
            out += self.c[j] * x[self.col[j]]
        return out

    def ctr(self, r):
        out = np.bincount(self.col[0], weights=self.c[0] * r, minlength=self.n)
        for j in range(1, 8):
            out += np.bincount(self.col[j], weights=self.c[j] * r, minlength=self.n)
        return out

    def apply(self, x):
        return self.d * x + self.ctr(self.lam * self.cx(x))

    def solve(self, b, x, tolerance, max_iterations, start=None):
        """Preconditioned conjugate gradients from ``x`` (changed in place), until the preconditioned
        residual r' M^-1 r is ``tolerance``^2 of ``start`` (None: of its own at ``x``):
        (x, iterations, residual / start, start)."""
        r = b - self.apply(x)
        z = r / self.diag
        p = z.copy()
        rz = _dot(r, z)
        rz0 = rz if start is None else start
        it = 0
        while it < max_iterations and rz > (tolerance ** 2) * rz0 and rz > 0:
            q = self.apply(p)
            alpha = rz / _dot(p, q)
            x += alpha * p
            r -= alpha * q
            z = r / self.diag
            rz_new = _dot(r, z)
            p *= rz_new / rz
            p += z
            rz = rz_new
            it += 1
        return x, it, math.sqrt(rz / rz0) if rz0 > 0 else 0.0, rz0


def fix_seams(values, stderr, mask, lookups, *, owner=None, value_range=(0.0, 1.0), seam_weight=SEAM_WEIGHT,
              margin_weight=MARGIN_WEIGHT, tolerance=TOLERANCE, max_iterations=MAX_ITERATIONS, out=None,
              stderr_out=None):
    """Adjust the texels the seam lookups read so that both sides of every seam agree.

    Minimises, over the texels x that the lookups read (the others stay bit-equal),

        sum_points seam_weight * length_k * (lookup_A(x) - lookup_B(x))^2 / s_ref^2
        + sum_covered (x_i - y_i)^2 / s_i^2 + sum_margin margin_weight * (x_i - y_i)^2 / s_ref^2

    with y the baked values, s_i each covered texel's standard error and s_ref their median: a
    texel moves in proportion to its error, a margin texel freely. Points on creases (see
    :class:`SeamLookups`) take no part: the AO may differ across them. Covered texels with no error
    (exactly open or occluded) are held, as are texels ``owner`` gives to another target than the
    lookup's. Solved by conjugate gradients with a Jacobi preconditioner, in float64, in a fixed
    order (the same bits for any threads); the result is clipped to ``value_range``. The error of a
    covered texel the fix changed by d becomes sqrt(s_i^2 + d^2), never less than its mean squared
    error: the fix's noise is at most the estimate's, and d estimates the bias it adds without bias.

    Parameters
    ----------
    values, stderr, mask : (H, W) or (N, H, W) arrays (one channel): the map, its standard error,
        the covered texels.
    lookups : :class:`core.geometry.seams.SeamLookups` of the same shape.
    owner : None, or (H, W) / (N, H, W) int: the target owning each texel (-1: none); a texel
        owned by another target than a lookup's is held.
    out, stderr_out : arrays to write the fixed map and error into (may be ``values`` and
        ``stderr`` themselves); None: copies.

    Returns
    -------
    (fixed values, its stderr, SeamFix)
    """
    values = np.asarray(values)
    out = values.copy() if out is None else out
    if out is not values:
        np.copyto(out, values)
    stderr = np.asarray(stderr)
    se_out = stderr.copy() if stderr_out is None else stderr_out
    if se_out is not stderr:
        np.copyto(se_out, stderr)
    if lookups.crease is not None and lookups.crease.any():
        lookups = lookups.subset(~lookups.crease)
    before = lookups.mismatch(values)
    none = SeamFix(np.zeros(0, np.int64), 0, 0.0, before, before, 0, 0, lookups.points)
    if not lookups.points:
        return out, se_out, none
    flat = values.reshape(-1), stderr.reshape(-1), np.asarray(mask).reshape(-1)
    lo, hi = value_range
    # Bounds by an active set: texels the solution takes past a bound are held there and the rest
    # solved again (from where they were), until none crosses or BOUND_ROUNDS have been solved.
    pinned, total, start = None, 0, None
    sys_ = None
    for round_ in range(BOUND_ROUNDS):
        sys_ = None  # the last round's system goes before the next is built
        sys_ = _System(*flat, lookups, owner, seam_weight, margin_weight, pinned)
        if round_ == 0:
            if sys_.n == 0:
                return out, se_out, none
            y0, solvable = flat[0][sys_.touched].astype(np.float64), sys_.solvable
            current = y0.copy()
        # From where the texels are, to the first solve's residual times the tolerance.
        x, it, res, start = sys_.solve(sys_.b, current[sys_.free], tolerance, max_iterations, start)
        total += it
        current[sys_.free] = x
        cross = np.flatnonzero(sys_.free)[(x < lo) | (x > hi)]
        if not len(cross):
            break
        held = np.clip(current[cross], lo, hi)
        current[cross] = held
        pinned = (cross, held) if pinned is None else (np.concatenate([pinned[0], cross]),
                                                      np.concatenate([pinned[1], held]))
    current = np.clip(current, lo, hi)
    texels = sys_.touched[solvable]
    new = current[solvable].astype(out.dtype)
    out.reshape(-1)[texels] = new
    # The error of a changed covered texel: its noise is at most the estimate's (A >= D, so the
    # fixed value's variance diag(A^-1 D A^-1) <= diag(A^-1) <= s_i^2), and the change d = x - y is
    # an unbiased estimate of the bias the fix adds (E[x] - t = E[x - y]), so
    # E[s_i^2 + d_i^2] = s_i^2 + bias^2 + var(d_i) >= the fixed value's mean squared error.
    cov = flat[2][texels]
    s0 = flat[1][texels[cov]].astype(np.float64)
    d = new[cov].astype(np.float64) - y0[solvable][cov]
    se_out.reshape(-1)[texels[cov]] = np.sqrt(s0 ** 2 + d * d).astype(se_out.dtype)
    after = lookups.mismatch(out)
    return out, se_out, SeamFix(texels, total, res, before, after, int(solvable.sum()), round_ + 1, lookups.points)


def fix_baked(target, ao, stderr, mask, tiles=None, owner=None):
    """Fix the seams of a baked map in place: :func:`fix_seams` over the lookups of ``target``'s seams
    (:func:`core.geometry.seams.seam_lookups`, Blender's defaults: Linear, Repeat) in ``ao`` ((H, W), or
    (N, H, W) UDIM tiles in the order of ``tiles``), ``stderr`` and ``mask`` the same shape. Returns
    the :class:`SeamFix`."""
    from ..geometry.seams import seam_lookups

    h, w = ao.shape[-2:]
    lookups = seam_lookups(target, (w, h), tiles=tiles, keep_points=False)
    _, _, info = fix_seams(ao, stderr, mask, lookups, owner=owner, out=ao, stderr_out=stderr)
    return info


__all__ = ["fix_seams", "fix_baked", "SeamFix", "SEAM_WEIGHT", "MARGIN_WEIGHT", "TOLERANCE", "MAX_ITERATIONS", "BOUND_ROUNDS"]
