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
#: MAX_ITERATIONS. The seams' mismatch is what the solve is for, and it is settled long before: at
#: 2048^2 (README Suzanne, 64 samples) 1e-3 takes 55 iterations and leaves the mismatch where 1e-6
#: (453 iterations) does, 0.00069 (0.0200 before); on the bench's Suzanne at 2048^2, 3e-3 takes 31
#: iterations to 1e-3's 61 for the same mismatch, 0.00046 (1e-2: 12, 0.00058), and at 256^2 the mean
#: distance from a 2048-sample bake moves by 1e-5 (0.01682 against 0.01681; raw 0.01701).
TOLERANCE = 3e-3
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
    A x = b, A = D + C^T diag(lam) C, applied without forming A: C as (8, K) weights (float32, as the
    lookups hold them) and unknown indices, worked column by column (a product is eight gathers added
    in order, a transpose eight bincounts, which add in the order of their input: the same bits on
    every numpy, and no temporary larger than a column). Held texels (no error, another target's) are
    constants in b; texels pinned at a bound later are masked out of the solve (:meth:`solve`)."""

    def __init__(self, flat_v, flat_s, flat_m, lookups, owner, margin, seam_weight, margin_weight):
        # The texels the lookups read: marked in one byte a texel (not sorted out of the 8 K indices).
        mark = np.zeros(flat_v.size, bool)
        for j in range(8):
            mark[lookups.index[:, j]] = True
        touched = np.flatnonzero(mark)
        del mark
        it = np.int32 if len(touched) < 2 ** 31 else np.int64
        pos = np.empty((8, lookups.points), it)
        for j in range(8):
            pos[j] = np.searchsorted(touched, lookups.index[:, j])
        y = flat_v[touched].astype(np.float64)
        s = flat_s[touched].astype(np.float64)
        covered = flat_m[touched]
        free = ~(covered & (s <= 0))
        if margin is not None:  # beyond the margin: the image as it was
            free &= within_margin(flat_m.reshape(lookups.shape), touched, margin)
        if owner is not None:
            own = np.asarray(owner).reshape(-1)[touched]
            free &= covered | (own >= 0)  # beyond every target's margin
            for j in range(8):
                other = (own[pos[j]] >= 0) & (own[pos[j]] != lookups.target)
                free[pos[j][other]] = False
        self.touched, self.free = touched, free
        self.n = n = int(free.sum())
        fi = (np.cumsum(free) - 1).astype(it)  # index among the unknowns
        cov_free = covered & free
        self.s_ref = s_ref = float(np.median(s[cov_free])) if cov_free.any() else 1.0
        self.covered = covered[free]
        self.d = np.where(covered, (s_ref / np.where(s > 0, s, s_ref)) ** 2, margin_weight)[free]
        self.lam = seam_weight * lookups.length
        self.c = np.empty((8, lookups.points), np.float32)
        self.col = pos  # becomes each entry's unknown, column by column
        g = np.zeros(lookups.points)  # the held texels' part of each difference
        for j in range(8):
            var = free[pos[j]]
            w = lookups.weight[:, j]
            g += np.where(var, 0.0, w.astype(np.float64) * y[pos[j]])
            self.c[j] = np.where(var, w, np.float32(0))
            self.col[j] = np.where(var, fi[pos[j]], 0)
        self.y = y[free]
        self.b = self.d * self.y - self.ctr(self.lam * g)
        self.diag = self.d.copy()
        for j in range(8):
            c = self.c[j].astype(np.float64)
            self.diag += np.bincount(self.col[j], weights=self.lam * c * c, minlength=n)

    def cx(self, x):
        out = np.take(x, self.col[0]) * self.c[0]
        for j in range(1, 8):
            out += np.take(x, self.col[j]) * self.c[j]
        return out

    def ctr(self, r):
        out = np.bincount(self.col[0], weights=self.c[0] * r, minlength=self.n)
        for j in range(1, 8):
            out += np.bincount(self.col[j], weights=self.c[j] * r, minlength=self.n)
        return out

    def apply(self, x):
        return self.d * x + self.ctr(self.lam * self.cx(x))

    def solve(self, x, active, tolerance, max_iterations, start=None):
        """Preconditioned conjugate gradients from ``x`` (changed in place) over the ``active``
        unknowns (1.0; 0.0: the others stay as they are in ``x``), until the preconditioned residual
        r' M^-1 r is ``tolerance``^2 of ``start`` (None: of its own at ``x``):
        (x, iterations, residual / start, start)."""
        r = (self.b - self.apply(x)) * active
        z = r / self.diag
        p = z.copy()
        rz = _dot(r, z)
        rz0 = rz if start is None else start
        it = 0
        while it < max_iterations and rz > (tolerance ** 2) * rz0 and rz > 0:
            q = self.apply(p)
            q *= active
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


def fix_seams(values, stderr, mask, lookups, *, owner=None, margin=None, value_range=(0.0, 1.0), seam_weight=SEAM_WEIGHT,
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
    owner : None, or (H, W) / (N, H, W) int: the target owning each texel, covered or margin (-1:
        none); a texel owned by another target than a lookup's is held, and so is an uncovered
        texel no target owns (beyond the margin: it keeps what the image had there).
    margin : None, or the margin (texels) the map was dilated by: an uncovered texel the margin
        did not reach (:func:`within_margin`) keeps its value. None (and no ``owner``): every texel
        the lookups read may move.
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
    sys_ = _System(*flat, lookups, owner, margin, seam_weight, margin_weight)
    if sys_.n == 0:
        return out, se_out, none
    # Bounds by an active set: texels the solution takes past a bound are held there and the rest
    # solved again from where they are, until none crosses or BOUND_ROUNDS solves are done; every
    # solve runs to the first one's residual times the tolerance.
    x = sys_.y.copy()
    active = np.ones(sys_.n)
    total, start = 0, None
    for round_ in range(BOUND_ROUNDS):
        x, it, res, start = sys_.solve(x, active, tolerance, max_iterations, start)
        total += it
        cross = (active > 0) & ((x < lo) | (x > hi))
        if not cross.any():
            break
        np.clip(x, lo, hi, out=x)
        active[cross] = 0.0
    np.clip(x, lo, hi, out=x)
    texels = sys_.touched[sys_.free]
    new = x.astype(out.dtype)
    out.reshape(-1)[texels] = new
    # The error of a changed covered texel: its noise is at most the estimate's (A >= D, so the
    # fixed value's variance diag(A^-1 D A^-1) <= diag(A^-1) <= s_i^2), and the change d = x - y is
    # an unbiased estimate of the bias the fix adds (E[x] - t = E[x - y]), so
    # E[s_i^2 + d_i^2] = s_i^2 + bias^2 + var(d_i) >= the fixed value's mean squared error.
    cov = flat[2][texels]
    s0 = flat[1][texels[cov]].astype(np.float64)
    d = new[cov].astype(np.float64) - sys_.y[cov]
    se_out.reshape(-1)[texels[cov]] = np.sqrt(s0 ** 2 + d * d).astype(se_out.dtype)
    after = lookups.mismatch(out)
    return out, se_out, SeamFix(texels, total, res, before, after, sys_.n, round_ + 1, lookups.points)


def within_margin(mask, index, margin):
    """Whether each texel of ``index`` (flat indices into ``mask``, (H, W) or (N, H, W) planes) is
    covered or one :func:`core.geometry.margin.dilate` fills with ``margin`` rings: its rings grow
    by the 8-neighbourhood inside the plane, so ring r holds the empty texels whose nearest covered
    texel is r rows or columns away (Chebyshev distance). Looked up ring by ring around the given
    texels alone (the seams' texels lie next to the islands: nothing the size of the image)."""
    mask = np.asarray(mask)
    h, w = mask.shape[-2:]
    flat = mask.reshape(-1)
    index = np.asarray(index, np.int64)
    plane, rest = np.divmod(index, h * w)
    y, x = np.divmod(rest, w)
    out = flat[index].copy()
    todo = np.flatnonzero(~out)
    for r in range(1, int(margin) + 1):
        if not len(todo):
            break
        py, px, pp = y[todo], x[todo], plane[todo]
        found = np.zeros(len(todo), bool)
        for dy in range(-r, r + 1):
            for dx in (range(-r, r + 1) if abs(dy) == r else (-r, r)):  # the ring's square border
                yy, xx = py + dy, px + dx
                ok = (yy >= 0) & (yy < h) & (xx >= 0) & (xx < w)
                at = (pp * h + np.where(ok, yy, 0)) * w + np.where(ok, xx, 0)
                found |= ok & flat[at]
        out[todo[found]] = True
        todo = todo[~found]
    return out


def fix_baked(target, ao, stderr, mask, tiles=None, owner=None, margin=None):
    """Fix the seams of a baked map in place: :func:`fix_seams` over the lookups of ``target``'s seams
    (:func:`core.geometry.seams.seam_lookups`, Blender's defaults: Linear, Repeat) in ``ao`` ((H, W), or
    (N, H, W) UDIM tiles in the order of ``tiles``), ``stderr`` and ``mask`` the same shape; ``owner``
    and ``margin`` as :func:`fix_seams` takes them. Returns the :class:`SeamFix`."""
    from ..geometry.seams import seam_lookups

    h, w = ao.shape[-2:]
    lookups = seam_lookups(target, (w, h), tiles=tiles, keep_points=False, creases=False)
    _, _, info = fix_seams(ao, stderr, mask, lookups, owner=owner, margin=margin, out=ao, stderr_out=stderr)
    return info


__all__ = ["fix_seams", "fix_baked", "within_margin", "SeamFix", "SEAM_WEIGHT", "MARGIN_WEIGHT", "TOLERANCE", "MAX_ITERATIONS", "BOUND_ROUNDS"]
