"""What a bake's result says in words: its summary line (occlusion_summary, parallel_words,
miss_summary), its notes about the input (input_notes) and its speed (throughput); the operator,
scripts/bake_ao.py and the batch say the same. Needs no bpy but for the scene's units (length_text)."""


# core's BakeResult.report keys that point at a problem in the input, and the sentence that says
# so: (one, several), each with {n} for the count.
_INPUT_NOTES = {
    "overlapping_texels": (
        "{n} texel lies under overlapping UV islands; it averages every surface over it",
        "{n} texels lie under overlapping UV islands; each averages every surface over it",
    ),
    "uv_outside_triangles": (
        "{n} triangle reaches outside the UV square [0, 1]; the part outside is not baked",
        "{n} triangles reach outside the UV square [0, 1]; the parts outside are not baked",
    ),
    "degenerate_uv_triangles": (
        "{n} triangle has no area in the UV map and was skipped",
        "{n} triangles have no area in the UV map and were skipped",
    ),
    "degenerate_triangles": (
        "{n} triangle has no area in space and was skipped",
        "{n} triangles have no area in space and were skipped",
    ),
}
# The same for the reports of core.bake_udim and core.bake_vertex_ao.
_TARGET_NOTES = {
    # UDIM bakes: reported instead of uv_outside_triangles.
    "uv_outside_udim_triangles": (
        "{n} triangle reaches outside the UDIM tiles (u in [0, 10], v in [0, 100]); the part outside is not baked",
        "{n} triangles reach outside the UDIM tiles (u in [0, 10], v in [0, 100]); the parts outside are not baked",
    ),
    # Colour-attribute bakes (core.bake_vertex_ao).
    "degenerate_corners": (
        "{n} face corner lies on a triangle with no area; its normal stands in for the face's",
        "{n} face corners lie on triangles with no area; their normals stand in for the faces'",
    ),
}


def throughput(result):
    """(mean samples per covered texel, million rays per second) of a bake result."""
    covered = result.samples[result.mask]
    per_texel = float(covered.mean()) if covered.size else 0.0
    rate = result.rays / result.seconds / 1e6 if result.seconds > 0 else float("nan")
    return per_texel, rate


def input_notes(result):
    """Warnings about the input from a bake result's report, as sentences.

    For example "163 texels lie under overlapping UV islands; each averages every surface over it".
    The operator and scripts/bake_ao.py both print these, after the object's name.
    """
    report = getattr(result, "report", None) or {}
    notes = []
    for key, (one, several) in {**_INPUT_NOTES, **_TARGET_NOTES}.items():
        n = report.get(key)
        if n:
            notes.append((one if n == 1 else several).format(n=n))
    # The core's own warnings (matching rays from behind the high-poly, worker processes not used, ...).
    return notes + miss_notes(result) + [str(w) for w in report.get("warnings", ())]


def length_text(value):
    """A world length as the scene's unit system writes it ("12.3 cm", "1.5 m"; "0.123 units" with
    units off, or without a scene)."""
    try:
        import bpy

        units = bpy.context.scene.unit_settings
        if units.system != "NONE":
            return bpy.utils.units.to_string(units.system, "LENGTH", value * units.scale_length, precision=3).strip()
    except (ImportError, AttributeError, TypeError, ValueError):
        pass
    return f"{value:.3g} units"


def thickness_summary(settings, result):
    """How far a thickness map's rays looked, as its summary says it: "rays into the mesh up to 9.11 cm
    (a twentieth of its size: set Distance for another)" where the core chose it (Distance unlimited),
    "... up to 50 cm" where Distance set it."""
    from .schema import unlimited

    distance = (getattr(result, "metadata", None) or {}).get("max_distance")
    if distance is None:
        return ""
    text = f"rays into the mesh up to {length_text(float(distance))}"
    if unlimited(settings.max_distance):
        text += " (a twentieth of its size: set Distance for another)"
    return text


def occlusion_summary(job, settings, result):
    """What occluded ``job``'s bake, as its summary line says it: "occluded by itself alone", "by 3
    other objects", "and the ground at 12 cm" (the height used: each object's lowest point with
    Ground Lowest Point); for a thickness map (the object alone, always) how far its rays looked."""
    if getattr(job, "quantity", "ao") != "ao":
        return thickness_summary(settings, result)
    if getattr(job, "highpoly", None):
        others = len(getattr(job, "occluders", ()))
        who = (f"occluded by the high-poly" + (f" and {others} other object{'s' if others != 1 else ''}"
                                               if others else ""))
    else:
        n = len(getattr(job, "occluders", ()))
        who = "occluded by itself alone" if not n else f"occluded by itself and {n} other object{'s' if n != 1 else ''}"
    height = (getattr(result, "metadata", None) or {}).get("ground_height")
    if settings.ground != "OFF" and height is not None:
        who += f" and the ground at {length_text(float(height))}"
    return who


def parallel_words(result):
    """Where a bake's tiles ran, for its summary after the time: " on 2 threads", " in 2 worker
    processes", and where the core chose between them (Processes 0 and Threads 0), its prediction of
    both: " on 2 threads (about 0.14 s against 0.66 s in 2 worker processes)". "" without the core's
    record (core.pipeline.result.BakeReport.parallel)."""
    report = getattr(result, "report", None) or {}
    p = report.get("parallel")
    if not p:
        return ""

    def where(processes, threads):
        each = f" of {threads} threads" if threads > 1 else ""
        return (f"on {threads} thread{'s' if threads != 1 else ''}" if processes == 1
                else f"in {processes} worker processes{each}")

    words = f" {where(p['processes'], p['threads'])}"
    predicted, options = p.get("predicted_seconds"), p.get("options")
    if predicted and options:
        chosen = "threads" if p["processes"] == 1 else "processes"
        other = "processes" if chosen == "threads" else "threads"
        words += (f" (about {predicted[chosen]:.2f} s against {predicted[other]:.2f} s "
                  f"{where(*options[other])})")
    return words


def miss_summary(result):
    """What the summary line says of a Selected to Active bake's matching rays: "; 312 of 65536
    sample points missed the high-poly", "; no sample point missed the high-poly", or "" for another bake."""
    report = getattr(result, "report", None) or {}
    cast = report.get("matching_rays", 0)
    if not cast:
        return ""
    missed = getattr(result, "missed", 0)
    auto = (getattr(result, "metadata", None) or {}).get("extrusion_auto") and "extrusion" in report
    measured = f"; extrusion {length_text(report['extrusion'])} measured from the meshes" if auto else ""
    if not missed:
        return f"{measured}; no sample point missed the high-poly"
    return f"{measured}; {missed} of {cast} sample points missed the high-poly"


def miss_notes(result):
    """Warnings of a Selected to Active bake (core.highpoly's report), as sentences; [] for another bake."""
    report = getattr(result, "report", None) or {}
    n = report.get("missed_texels", 0)
    if not n:
        return []
    return [f"{n} texel{' finds' if n == 1 else 's find'} no high-poly surface along {'its' if n == 1 else 'their'} "
            f"rays and {'is' if n == 1 else 'are'} left to the margin; a larger extrusion or max ray distance "
            "reaches farther"]
