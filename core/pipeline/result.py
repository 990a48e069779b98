"""What a bake returns: :class:`BakeResult` and its :class:`BakeReport`, one type each for every target."""

import dataclasses
from dataclasses import dataclass, field

import numpy as np


@dataclass
class BakeReport:
    """What a bake's input held and what the bake met (counts, not times), as named fields; a field is
    None where it does not apply to the bake (a corner bake has no texels, an image bake no corners).

    Images (and each UDIM tile): ``covered_texels``; ``degenerate_uv_triangles`` and
    ``degenerate_triangles`` (skipped: no area in the UV map, or in space); ``uv_outside_triangles``
    (with UVs outside [0, 1]: only their part inside is baked); ``overlapping_texels`` (under more than
    one UV island: averaged over all surfaces covering them).
    UDIM tiles: the tiles' counts added up, ``uv_outside_udim_triangles`` in place of
    ``uv_outside_triangles``, and ``tiles`` (the tile numbers baked).
    Face corners: ``corners``, ``sample_points`` (corners of one vertex and one normal share one),
    ``degenerate_corners`` (on a triangle of no area: their normal stands in for the face's).
    Selected to active: ``extrusion`` (world units; 0 with a cage) and ``extrusion_served`` (the share of
    points the automatic extrusion serves), ``matching_rays``, ``matching_rays_behind`` (met the
    high-poly from behind), ``missed_matching_rays``, ``missed_texels``, ``partly_missed_texels``,
    ``directions_per_point``, ``matching_seconds`` and ``matching_cpu_seconds`` (the matching's time).
    Atlases (several targets into one image, :mod:`core.pipeline.atlas`): ``atlas`` (a dict: ``targets``,
    ``baked`` and why (``why``), ``kept`` (and of those, ``held``: the
    targets an earlier bake held that this one does not name), each target's ``reach`` and ``owned`` texels, ``shared_texels``,
    ``unlimited_reach`` and its ``note``) and ``atlas_overlaps`` ([{``a``, ``b``, ``texels``}] per pair
    of targets whose UVs overlap).
    Fix Seams (images and UDIM tiles, once for all tiles): ``seam_points`` (points along the smooth UV
    seams, both sides looked up), ``seam_texels`` (texels solved for), ``seam_iterations`` (conjugate
    gradients, all bound rounds), ``seam_mismatch_before`` and ``seam_mismatch_after`` (mean |lookup A -
    lookup B| over the points: :mod:`core.geometry.seams`).
    Every bake: ``parallel`` (where its tiles ran, and why: ``processes`` (1: this process), ``threads``
    each, ``why`` (a sentence) and ``predicted_seconds`` (the model's time of each option weighed, when
    the bake chose between this process's threads and worker processes itself), from
    :func:`core.execution.executor.parallel_of`); ``worker_memory`` (one entry per process that held the bake,
    :func:`core.execution.memory.memory_entry`: ``process`` 'parent' or 'worker N', ``rss``, ``peak``,
    ``held`` bytes, a worker's ``start``, ``ready``, ``tiles``, ``scene_reused`` and ``request``, the
    options it baked with as plain data) and ``warnings`` (sentences naming the object; None when there
    is none).

    It also reads as a mapping of the fields that apply (``report["covered_texels"]``,
    ``report.get("warnings", [])``, ``"warnings" in report``, ``dict(report.items())``), as the report
    was before it had named fields.
    """

    covered_texels: int = None
    degenerate_uv_triangles: int = None
    degenerate_triangles: int = None
    uv_outside_triangles: int = None
    overlapping_texels: int = None
    uv_outside_udim_triangles: int = None
    tiles: list = None
    corners: int = None
    sample_points: int = None
    degenerate_corners: int = None
    extrusion: float = None
    extrusion_served: float = None
    matching_rays: int = None
    matching_rays_behind: int = None
    missed_matching_rays: int = None
    missed_texels: int = None
    partly_missed_texels: int = None
    directions_per_point: int = None
    matching_seconds: float = None
    matching_cpu_seconds: float = None
    atlas: dict = None
    atlas_overlaps: list = None
    parallel: dict = None
    seam_points: int = None
    seam_texels: int = None
    seam_iterations: int = None
    seam_mismatch_before: float = None
    seam_mismatch_after: float = None
    worker_memory: list = None
    warnings: list = None

    def warn(self, *sentences):
        """Add warnings (after any the bake has already)."""
        self.warnings = (self.warnings or []) + list(sentences)

    # -- read as a mapping of the fields that apply --------------------------------------------------------

    def keys(self):
        return [f.name for f in dataclasses.fields(self) if getattr(self, f.name) is not None]

    def items(self):
        return [(k, getattr(self, k)) for k in self.keys()]

    def __contains__(self, key):
        return key in _REPORT_FIELDS and getattr(self, key) is not None

    def __getitem__(self, key):
        if key not in self:
            raise KeyError(key)
        return getattr(self, key)

    def get(self, key, default=None):
        return getattr(self, key) if key in self else default

    def __iter__(self):
        return iter(self.keys())

    def __len__(self):
        return len(self.keys())

    def pop(self, key, *default):
        """The field's value, then None (as a dict's pop)."""
        if key not in self:
            if default:
                return default[0]
            raise KeyError(key)
        value = getattr(self, key)
        setattr(self, key, None)
        return value


_REPORT_FIELDS = {f.name for f in dataclasses.fields(BakeReport)}


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
    report : a :class:`BakeReport`: counts of what the input held (degenerate UV triangles skipped,
        triangles of zero area in space skipped, triangles with UVs outside [0, 1], texels covered by
        more than one UV island, covered texels), selected to active's figures, the memory of every
        process that held the bake (``worker_memory``: a worker's peak is its bake's own, from
        ``start``, its size before it built the scene; ``ready``, after; ``held``, the bytes of the
        arrays its bake holds, Embree's scenes aside) and the warnings.
    bent : None, or with ``bent_normals``, (H, W, 3) float32 unit bent normals in the bake's
        ``bent_space`` (covered and margin texels; zero elsewhere), see :mod:`core.post.bent`.

    raw_ao, raw_stderr : with ``denoise``, the estimate and its error before the filter (``ao`` and
        ``stderr`` are then the denoised map and its error); None otherwise.
    owner, targets, record : an atlas (a list of targets baked into one image) only, else None:
        ``owner`` (H, W) int32, the index into ``targets`` of the target owning each covered and
        margin texel, -1 elsewhere; ``targets`` the targets' names (the list's, then any target an
        earlier bake held and this one kept); ``record`` the :class:`core.files.atlasrecord.AtlasRecord`
        a rebake starts from (``keep=``). ``report['atlas']`` says which targets were baked and why,
        which were kept, each target's reach; ``report['atlas_overlaps']`` the pairs of targets whose
        UVs overlap, with their texel counts. See :mod:`core.pipeline.atlas`.

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
    report: BakeReport = field(default_factory=BakeReport)
    bent: np.ndarray = None
    miss: np.ndarray = None
    missed: int = 0
    unit: np.ndarray = None
    tiles: dict = None
    raw_ao: np.ndarray = None
    raw_stderr: np.ndarray = None
    owner: np.ndarray = None
    targets: tuple = None
    record: object = None

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




def seam_report(fix):
    """The report's Fix Seams fields of a :class:`core.post.fixseams.SeamFix` (none for None)."""
    if fix is None:
        return {}
    return dict(seam_points=fix.points, seam_texels=fix.unknowns, seam_iterations=fix.iterations,
                seam_mismatch_before=fix.before, seam_mismatch_after=fix.after)


__all__ = ["BakeResult", "BakeReport", "empty_reason", "seam_report"]
