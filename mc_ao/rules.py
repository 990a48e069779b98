"""Every rule between bake settings (and between the script's own options and the settings), once.

A :class:`Rule` says when a combination is refused and why, in words that follow the name of the
setting the problem is said of. Each front end names the settings its own way: the panel by their
labels ("UDIM Tiles", "Target" "Image Textures"), the script by its options ("--udim", "--target"
"image-textures"); a message names them by placeholders that the front end's naming fills in
(mc_ao.schema.label_of, option_of):

    "{use_udim}"              a setting's (or a script option's) name
    "{target:IMAGE_TEXTURES}" one of an enum's choices
    "{v.into!r}"              a value of the settings being checked
    "{c}"                     a rule that is broken several ways at once: the case (see ``broken``)

mc_ao.schema.problems checks every setting's value, then these rules: the operator before it bakes
(the rules marked ``poll`` already grey out its button, with the same words), the script and the
batch manifest before anything runs (with ``script``: the rules of the script's options too). No bpy.
"""

import os
from dataclasses import dataclass
from string import Formatter
from typing import Callable

from . import corelink

__all__ = ["Rule", "RULES", "broken"]


@dataclass(frozen=True)
class Rule:
    """One rule between settings.

    field : the setting (or script option) the problem is said of; the message follows its name.
    broken : ``values -> bool`` (or a value taken as one), or a list of cases (each one problem, ``{c}``
        in the message).
    message : the problem (see the module's docstring for its placeholders).
    script : a rule of the script's own options (``--format``, ``--save``, ``--match-suffix``, ...)
        or of settings that the panel hides where they do not apply (the operator leaves those
        alone); checked for the script and the batch only.
    poll : the Bake AO button's poll says it (the button greys out with it before the selection's
        reason).
    """

    field: str
    broken: Callable
    message: str
    script: bool = False
    poll: bool = False


def _quantities(v):
    return (v.quantity,) if isinstance(v.quantity, str) else tuple(v.quantity)


def _vertex(v):
    return v.target == "VERTEX_COLORS"


def _bits_cases(v):
    """(format, the bits it takes) of each chosen image format that cannot take --bits (core.files.imageio's
    table: 8, 16, "half", "float", the --bits choices as numbers)."""
    if v.bits is None:
        return []
    formats = corelink.load("files.imageio").FORMATS
    cases = []
    for fmt in v.format:
        if fmt == "ply":
            continue
        allowed = [str(b) for b in formats["." + fmt][0]]
        if v.bits not in allowed:
            cases.append((fmt, " or ".join(allowed)))
    return cases


_IMAGES_ONLY = "bakes images; {target} {target:VERTEX_COLORS} bakes a color attribute"


_S2A = "bakes AO into one image texture of the low-poly: "
_S2A_OFF = "is a setting of {use_selected_to_active} (or {match_suffix}), which is off"

RULES = (
    # -- what goes where ------------------------------------------------------------------------
    Rule("attribute_name", lambda v: _vertex(v) and not str(v.attribute_name).strip(),
         "must name the color attribute to bake into, not be empty"),
    Rule("use_selected_to_active", lambda v: v.use_selected_to_active and _vertex(v),
         _S2A + "set {target} to {target:IMAGE_TEXTURES}", poll=True),
    Rule("use_selected_to_active", lambda v: v.use_selected_to_active and v.use_udim,
         _S2A + "turn off {use_udim}", poll=True),
    Rule("use_selected_to_active", lambda v: v.use_selected_to_active and v.bent_normals,
         _S2A + "turn off {bent_normals}", poll=True),
    # -- occluders, ground, quantities, channel ---------------------------------------------------
    Rule("exclude_collections",
         lambda v: [", ".join(repr(n) for n in sorted(set(v.occluder_collections) & set(v.exclude_collections)))]
         if set(v.occluder_collections) & set(v.exclude_collections) else [],
         "names {c}, which the included collections name too: a collection either occludes or not; remove it "
         "from one list"),
    Rule("bent_normals", lambda v: "THICKNESS" in _quantities(v) and v.bent_normals,
         "come from the AO's rays: bake Thickness without Bent Normals"),
    Rule("quantity", lambda v: len(_quantities(v)) > 1 and _vertex(v),
         "bakes one quantity into a color attribute: choose AO or Thickness"),
    Rule("quantity", lambda v: len(_quantities(v)) > 1 and v.use_selected_to_active,
         "bakes one quantity with Selected to Active: choose AO or Thickness"),
    Rule("into", lambda v: v.channel != "NONE" and not v.into, "must name the image whose channel receives the AO"),
    Rule("channel", lambda v: v.channel != "NONE" and (_vertex(v) or v.use_udim),
         "writes into one image: not with color attributes or UDIM tiles"),
    Rule("channel", lambda v: v.channel != "NONE" and _quantities(v) != ("AO",), "takes the AO alone: set Quantity to AO"),
    Rule("into", lambda v: v.channel == "NONE" and bool(v.into),
         "names {v.into!r} but Channel is off: choose the channel to write into"),
    Rule("samples", lambda v: v.denoise and v.samples < 2,
         "must be at least 2 with {denoise}: the filter weighs each texel by its error, which takes two sets of "
         "samples; raise {samples} or turn {denoise} off"),
    Rule("error_map", lambda v: _vertex(v) and v.error_map,
         "is for image textures: a color-attribute bake has no image to hold the standard error; turn it off "
         "(adaptive sampling still uses the error)"),
    # -- shared images (atlases) -----------------------------------------------------------------
    Rule("images", lambda v: v.images != "OWN" and _vertex(v),
         "bakes images into shared images: set {target} to {target:IMAGE_TEXTURES}", poll=True),
    Rule("images", lambda v: v.images != "OWN" and v.use_udim,
         "bakes one image over the UV square, not UDIM tiles: turn off {use_udim}", poll=True),
    Rule("atlas", lambda v: v.images == "ATLAS" and not str(v.atlas).strip(),
         "must name the image every object bakes into, not be empty"),
    Rule("atlas", lambda v: v.images == "ATLAS" and "{object}" in str(v.atlas),
         "{v.atlas!r} names one image for every object: leave out {{object}}"),
    Rule("id_map", lambda v: v.id_map and v.images == "OWN",
         "shows which object owns each texel of a shared image: set {images} to {images:ATLAS} or {images:NODE}"),
    # -- the script's options: Selected to Active ------------------------------------------------
    Rule("active", lambda v: not v.use_selected_to_active and v.active is not None, _S2A_OFF, script=True),
    Rule("cage", lambda v: not v.use_selected_to_active and v.cage is not None, _S2A_OFF, script=True),
    Rule("cage_extrusion", lambda v: not v.use_selected_to_active and v.cage_extrusion != 0.0, _S2A_OFF,
         script=True),
    Rule("max_ray_distance", lambda v: not v.use_selected_to_active and v.max_ray_distance != 0.0, _S2A_OFF,
         script=True),
    Rule("match_suffix", lambda v: bool(v.match_suffix) and (not all(v.match_suffix)
                                                            or v.match_suffix[0] == v.match_suffix[1]),
         "needs two different, non-empty suffixes, not {v.match_suffix[0]!r} and {v.match_suffix[1]!r}", script=True),
    Rule("match_collections", lambda v: v.match_collections and bool(v.match_suffix),
         "pairs each low-poly with the objects of its collection; {match_suffix} pairs them by name: give one",
         script=True),
    Rule("match_collections", lambda v: v.match_collections and not v.objects,
         "needs {objects}: the low-poly objects, each baked from the other objects of its collection", script=True),
    Rule("active", lambda v: v.match_collections and v.active is not None,
         "names one low-poly; with {match_collections}, {objects} names the low-poly objects", script=True),
    Rule("active", lambda v: bool(v.match_suffix) and v.active is not None,
         "names one low-poly; with {match_suffix}, {objects} names the low-poly objects", script=True),
    Rule("cage", lambda v: bool(v.match_suffix) and bool(v.cage),
         "NAME names one cage for one low-poly; bake a pair with a cage object with {active} ({cage} alone "
         "extrudes each low-poly along its vertex normals)", script=True),
    Rule("cage", lambda v: (v.use_selected_to_active and not v.match_suffix and bool(v.cage)
                            and (v.cage == v.active or v.cage in (v.objects or []))),
         "{v.cage!r} is also the low-poly or one of the high-poly objects", script=True),
    Rule("active", lambda v: v.use_selected_to_active and v.active is not None and v.active in (v.objects or []),
         "{v.active!r} is also among {objects} (the high-poly objects)", script=True),
    # -- the script's options: files -------------------------------------------------------------
    Rule("format", lambda v: [" ".join(f for f in v.format if f != "ply")]
         if _vertex(v) and any(f != "ply" for f in v.format) else [],
         "{c}: {target} {target:VERTEX_COLORS} writes .ply files ({format} ply)", script=True),
    Rule("use_udim", lambda v: _vertex(v) and v.use_udim, _IMAGES_ONLY, script=True),
    Rule("bent_normals", lambda v: _vertex(v) and v.bent_normals, _IMAGES_ONLY, script=True),
    Rule("format", lambda v: not _vertex(v) and "ply" in v.format,
         "ply is for {target} {target:VERTEX_COLORS}; images are written as png, exr or tif", script=True),
    Rule("save", lambda v: v.save is not None and not _vertex(v),
         "writes color attributes into a .blend file: it needs {target} {target:VERTEX_COLORS}", script=True),
    Rule("save", lambda v: v.save is not None and _vertex(v) and os.path.splitext(v.save)[1].lower() != ".blend",
         "{v.save!r} must name a .blend file", script=True),
    Rule("bits", _bits_cases, "{v.bits} cannot be written as {c[0]}: {c[0]} files take {bits} {c[1]}", script=True),
    Rule("image_name", lambda v: any(sep in v.image_name for sep in "/\\") or v.image_name in (".", ".."),
         "{v.image_name!r} is a path: give a name; files go into {output}", script=True),
    Rule("atlas", lambda v: v.images == "ATLAS" and (any(sep in v.atlas for sep in "/\\") or v.atlas in (".", "..")),
         "{v.atlas!r} is a path: give a name; files go into {output}", script=True),
)


class _Name:
    """A setting in a message: its name, or (with a format spec) one of its choices, as ``naming`` says."""

    def __init__(self, naming, name):
        self.naming, self.name = naming, name

    def __format__(self, spec):
        return self.naming(self.name, spec or None)


class _Fields(dict):
    """format_map's fields: ``v`` the values, ``c`` the case, any other name a setting."""

    def __init__(self, naming, values, case):
        super().__init__(v=values, c=case)
        self.naming = naming

    def __missing__(self, name):
        return _Name(self.naming, name)


def broken(values, naming, *, script=False, poll=False):
    """The rules ``values`` break: ``[(field, message)]``, each message following its field's name
    as ``naming`` writes it. ``script``: with the script's options' rules (``values`` then has those
    options too); ``poll``: only the rules of the Bake AO button's poll."""
    out = []
    for rule in RULES:
        if (rule.script and not script) or (poll and not rule.poll):
            continue
        cases = rule.broken(values)
        if not isinstance(cases, list):  # broken or not (a bool, or a value that says it)
            cases = [None] if cases else []
        for case in cases:
            out.append((rule.field, Formatter().vformat(rule.message, (), _Fields(naming, values, case))))
    return out
