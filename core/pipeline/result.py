"""What a bake returns: :class:`BakeResult`, one type for every target (images, UDIM tiles, face corners)."""

from dataclasses import dataclass, field

import numpy as np


@dataclass
class BakeResult:
    """What a bake returns. Arrays are (H, W), row 0 is v = 0 (Blender's pixel order).

    ao : float32 in [0, 1]; covered texels hold their estimate, margin texels the dilated value,
        the rest 0.
    mask : bool, texels a UV triangle covers.
    stderr : float32, each covered texel's standard error (0 elsewhere): the error its estimate
        makes, with replicates (see :func:`bake_ao`); an upper bound for the quasi-Monte Carlo
        sources without (``metadata['error_estimate']`` says which).
    samples : int32, samples taken per covered texel (0 elsewhere).
    rays : rays handed to Embree (a direction below the geometric surface goes with length 0 and
        counts as occluded).
    seconds : wall time of the bake; trace_seconds : time inside embreex, summed over threads;
    trace_cpu_seconds : the same in thread CPU time (steadier on a shared machine).
    metadata : settings and version, for image files.
    miss : selected to active only (else None): bool, texels a UV triangle covers where no sample
        point's matching ray found the high-poly surface; they are not in ``mask`` (the margin
        fills them). See :mod:`core.highpoly`.
    missed : selected to active only: sample points whose matching ray missed (each point carries a
        block of samples, ``report['directions_per_point']``; none of them is traced).
    report : counts of what the input held: degenerate UV triangles skipped, triangles of zero area
        in space skipped (they have no surface), triangles with UVs
        outside [0, 1] (only their part inside the image is baked), texels covered by more than one
        UV island (averaged over all surfaces covering them), covered texels. ``worker_memory``:
        one dict per process that held the bake (this one, ``process`` 'parent', then each worker,
        'worker N'): ``rss`` and ``peak`` resident bytes (VmRSS and VmHWM; a worker's peak is its
        bake's own, from ``start``, its size before it built the scene; ``ready``, after), and
        ``held``, the bytes of the arrays its bake holds (meshes, tables; Embree's scenes are not
        arrays and are in ``ready - start``, unless the worker kept them from its last bake):
        :func:`core.execution.memory.memory_entry`; a worker's also ``tiles`` (how many it baked) and
        ``scene_reused`` (whether it traced in the Embree scenes it kept from its last bake of the
        same meshes).
    bent : None, or with ``bent_normals``, (H, W, 3) float32 unit bent normals in the bake's
        ``bent_space`` (covered and margin texels; zero elsewhere), see :mod:`core.post.bent`.

    raw_ao, raw_stderr : with ``denoise``, the estimate and its error before the filter (``ao`` and
        ``stderr`` are then the denoised map and its error); None otherwise.

    The same type for every target. Mesh corners (:func:`core.bake_vertex_ao`): the arrays are per
    corner, (C,) (``bent`` (C, 3)), ``mask`` all true, and ``unit`` (C,) int64 names the sample point
    whose estimate each corner has (corners of one vertex and one normal share one). UDIM tiles
    (:func:`core.bake_udim`): ``tiles`` maps each tile number to its own BakeResult, the arrays are the
    tiles' stacked, (N, H, W) in the order of ``tiles``, and the times and rays are their sums.
    """

    ao: np.ndarray
    mask: np.ndarray
    stderr: np.ndarray
    samples: np.ndarray
    rays: int
    seconds: float
    trace_seconds: float
    threads: int
    trace_cpu_seconds: float = 0.0
    metadata: dict = field(default_factory=dict)
    report: dict = field(default_factory=dict)
    bent: np.ndarray = None
    miss: np.ndarray = None
    missed: int = 0
    unit: np.ndarray = None
    tiles: dict = None
    raw_ao: np.ndarray = None
    raw_stderr: np.ndarray = None

    @property
    def rays_per_second(self):
        return self.rays / self.seconds if self.seconds > 0 else float("nan")


def empty_reason(no_area=0, no_uv_area=0, outside=0, outside_udim=0):
    """Why a bake covered nothing, from the counts its report gives (one wording for the core and the
    add-on)."""
    reasons = [f"{n} {text}" for n, text in (
        (no_area, "of its triangles have no area"),
        (no_uv_area, "of its UV triangles have no area in the UV map"),
        (outside, "of its UV triangles lie outside the image's UV square [0, 1]"),
        (outside_udim, "of its UV triangles lie outside the UDIM tiles 1001 to 2000")) if n]
    return "; ".join(reasons) or "its UV triangles are too small to cover a texel centre at this resolution"


__all__ = ["BakeResult", "empty_reason"]
