"""Every bake setting once: name, type, default, limits, help, the script option and manifest key that
set it, and the targets it applies to; the script's own options (what to bake, where files go), with
their manifest keys; how each front end names a setting. No bpy.

Made from these lists: the scene's property group (mc_ao.properties), the fields of
mc_ao.settings.BakeSettings, scripts/bake_ao.py's options (mc_ao.cli.options) and with them the batch
manifest's keys (a manifest key is the option's name with '_' for '-': :func:`manifest_keys`), and
the one check of every value before any work (:func:`problems`, with the rules between settings of
mc_ao.rules).

The bake's own options are the core's: :data:`core.base.request.OPTIONS` (numpy-free, read when this
module loads, before the core's dependencies) defines each once, with its type, default, limits and
meaning. A setting that gives one names it (``core``) and takes its limits from it unless it says
otherwise; a core option that no setting maps, and that is not one the add-on decides itself
(:data:`CORE_INTERNAL`), becomes a setting of its own (its name, label, help, limits and choices from
the core), so a new option of the core reaches the panel's properties, the script's options, the
manifest keys and the core call (mc_ao.settings.BakeSettings.bake_kwargs) with no edit here.

"No distance limit" has one meaning for every distance here: 0 or infinity (:func:`unlimited`).
"""

import dataclasses
import math
from dataclasses import dataclass, field

from . import corelink, rules

#: The core's options of a bake (core.base.request: no numpy).
request = corelink.load("base.request")

__all__ = ["Setting", "SETTINGS", "BY_NAME", "BY_KEY", "Option", "OPTIONS", "OPTION_BY_KEY", "problems",
           "unlimited", "limit", "cli_value", "from_cli", "from_options", "manifest_keys", "label_of", "option_of",
           "FORMATS", "BITS", "MAX_THREADS"]

#: The most threads a bake may ask for (the core's).
MAX_THREADS = request.MAX_THREADS


@dataclass(frozen=True)
class Setting:
    """One bake setting.

    name : the BakeSettings field and the scene property (``scene.mc_ao.<name>``).
    kind : "int", "float", "distance" (a float where 0 and inf mean no limit), "bool", "enum", "str",
        "object" (an object's name; a pointer on the scene), "image" (an image's name; a pointer on the
        scene), "collections" (collection names; a list of collection pointers on the scene) or "flags"
        (a set of an enum's identifiers: a tuple here, an enum-flag property on the scene).
    default, label (the UI's name), help (the UI's tooltip and the option's help).
    lo, hi : limits of an int or float (a float with ``lo`` None takes any finite number); None: the
        core option's (``core``).
    zero : what 0 means, said in messages ("every core").
    items : an enum's ``(identifier, UI name, description)``; the script's choice for an identifier is
        it in lower case with '-' for '_' (``VERTEX_COLORS`` -> ``vertex-colors``).
    key : the script option's name with '_' for '-', and the manifest key; None for a setting of the
        panel only (the script sets it another way, e.g. ``--format``, or not at all).
    targets : where it applies: "image", "vertex", "udim", "bent", "selected_to_active", "all".
    ui : further keyword arguments of the Blender property (soft limits, subtype, unit, ...).
    flag : for an enum, the identifier that its script option, a flag (``--ground``), chooses; absent,
        the default. None: the option takes the choice as a value.
    sets : ``(name, identifier)``: giving this setting's option also sets that enum setting
        (``--ground-height H`` sets Ground to Height); its option's default is then None (not given).
    cli_help : the option's help where ``help``'s words are the panel's (a click, a panel-only
        setting); absent, the option's help is ``help`` with other settings' names as their options
        (mc_ao.cli.options.script_help).
    core : the option of core.base.request.OPTIONS that this setting gives (through
        BakeSettings.bake_kwargs), or None.
    """

    name: str
    kind: str
    default: object
    label: str
    help: str
    lo: object = None
    hi: object = None
    zero: str = ""
    items: tuple = ()
    key: object = ""  # "" = the name
    targets: tuple = ("all",)
    ui: dict = field(default_factory=dict)
    flag: object = None
    sets: tuple = ()
    cli_help: str = ""
    core: object = None

    @property
    def option_key(self):
        """The option's dest and manifest key, or None."""
        return None if self.key is None else (self.key or self.name)

    @property
    def option(self):
        return None if self.option_key is None else "--" + self.option_key.replace("_", "-")

    @property
    def identifiers(self):
        return tuple(i[0] for i in self.items)


def cli_value(identifier):
    """The script's choice for an enum identifier: ``VERTEX_COLORS`` -> ``vertex-colors``."""
    return identifier.lower().replace("_", "-")


def from_cli(setting, value):
    """A script option's value as the setting holds it (an enum's identifier from its choice, a flag's
    identifier from True or False, a tuple from a list, the default for an option not given)."""
    if value is None and setting.sets:
        return setting.default
    if setting.kind == "enum" and setting.flag is not None:
        return setting.flag if value is True else (setting.default if value is False else value)
    choices = {cli_value(i): i for i in setting.identifiers}
    if setting.kind == "enum":
        return choices.get(value, value)
    if setting.kind == "flags":
        return tuple(choices.get(v, v) for v in ([value] if isinstance(value, str) else value))
    if setting.kind == "collections":
        return tuple([value] if isinstance(value, str) else value)
    return value


def from_options(namespace):
    """The settings the script's options give: ``({name: value}, [problem, ...])`` for every setting
    with an option. An option that ``sets`` another setting (``--ground-height H``: Ground is Height)
    sets it; given beside that setting's own flag it is a problem."""
    values, out = {}, []
    for setting in SETTINGS:
        if setting.option_key is not None:
            values[setting.name] = from_cli(setting, getattr(namespace, setting.option_key))
    for setting in SETTINGS:
        if setting.sets and setting.option_key is not None and getattr(namespace, setting.option_key) is not None:
            name, identifier = setting.sets
            other = BY_NAME[name]
            if other.flag is not None and getattr(namespace, other.option_key) is True:
                out.append(f"{other.option} and {setting.option} both place the {other.label.lower()}: give one "
                           f"({other.option} at each object's lowest point, {setting.option} at a fixed height)")
            values[name] = identifier
    return values, out


SETTINGS = (
    Setting("samples", "int", 128, "Samples", "Rays per texel (the most, when adaptive sampling stops early)",
            core="samples", ui={"soft_max": 4096}),
    Setting("min_samples", "int", 16, "Min Samples", "Rays per texel before adaptive sampling may stop a texel",
            hi=request.MAX_SAMPLES, core="min_samples", ui={"soft_max": 1024}),
    Setting("target_error", "float", 0.0, "Noise Threshold",
            "Adaptive sampling: stop a texel once its AO is known to within this, 95% of the time (0.01: "
            "+-0.01). Open and fully occluded areas stop at Min Samples, noisy ones take up to Samples. With "
            "Denoise on, the denoised AO: texels the denoiser can average stop sooner, detailed ones take more. "
            "0 turns adaptive sampling off", zero="adaptive sampling off", core="target_error",
            ui={"max": 1.0, "soft_max": 0.1, "step": 0.1, "precision": 4}),
    Setting("resolution", "int", 1024, "Size",
            "Width of the image in pixels. An existing image of another size is resized to this size (and "
            "put back as it was if its bake is cancelled or fails)", lo=1, hi=request.MAX_RESOLUTION, key=None,
            core="resolution",
            targets=("image",), ui={"soft_min": 16, "soft_max": 8192, "subtype": "PIXEL"}),
    Setting("height", "int", 0, "Height", "Height of the image in pixels; 0 makes it square", lo=0,
            hi=request.MAX_RESOLUTION, zero="as wide as high", key=None, targets=("image",), core="resolution",
            ui={"soft_max": 8192, "subtype": "PIXEL"}),
    Setting("max_distance", "distance", 0.0, "Distance",
            "Occluders farther than this do not count; 0 (or inf) = no limit (a thickness map then looks a "
            "twentieth of the object's size into it)", core="max_distance",
            ui={"soft_max": 100.0, "subtype": "DISTANCE", "unit": "LENGTH"}),
    Setting("source", "enum", "SOBOL", "Sampler", "Where each texel's sample points come from", core="source", items=(
        ("SOBOL", "Sobol'", "Owen-scrambled Sobol' points over position and direction (least noise)"),
        ("HALTON", "Halton", "Scrambled Halton points"),
        ("STRATIFIED", "Stratified", "Jittered strata"),
        ("INDEPENDENT", "Independent", "Independent uniform random points"))),
    Setting("distribution", "enum", "COSINE", "Directions", "How ray directions are spread over the hemisphere",
            core="distribution",
            items=(("COSINE", "Cosine", "Cosine-weighted: no noise on open surfaces"),
                   ("UNIFORM", "Uniform", "Uniform over the hemisphere"))),
    # "VISIBLE" (the script's "visible") is the stored value of All Rendered: files and manifests that
    # chose it keep it.
    Setting("occluders", "enum", "VISIBLE", "Occluders",
            "What casts occlusion onto the baked objects: every object that renders (default), the baked "
            "objects (selected), or each object alone (self); Include and Exclude narrow it to collections",
            items=(
                ("SELF", "Object Alone", "Each object occludes only itself"),
                ("SELECTED", "Selected", "The selected objects occlude each other"),
                ("VISIBLE", "All Rendered",
                 "Every object that renders in the view layer, as Cycles' bake counts them: hidden ones too, "
                 "not those disabled in renders"))),
    Setting("occluder_collections", "collections", (), "Include",
            "Only objects in these collections (and the collections inside them) occlude; none listed: "
            "every object of the Occluders choice. An instance belongs to its instancer's collections"),
    Setting("exclude_collections", "collections", (), "Exclude",
            "Objects in these collections (and the collections inside them) do not occlude other objects. "
            "Where an object lies in both an included and an excluded collection, the collection nearer to "
            "it decides (exclude a collection inside an included one to carve it out)"),
    Setting("only_local", "bool", False, "Only Local",
            "Each object is occluded by itself alone, as Cycles' Ambient Occlusion node's Only Local: no "
            "other object darkens it (Occluders and the collections are then not used)"),
    Setting("ground", "enum", "OFF", "Ground",
            "A ground plane that occludes as an endless floor mesh would, without a mesh: contact shadow for "
            "props baked without their floor", flag="AUTO", core="ground", items=(
                ("OFF", "Off", "No ground"),
                ("AUTO", "Lowest Point", "At each baked object's own lowest point (each prop of a batch "
                                         "gets its own contact)"),
                ("HEIGHT", "Height", "At the height below (world Z)"))),
    Setting("ground_height", "float", 0.0, "Height",
            "World Z of the ground plane when Ground is Height (the script's --ground-height H sets both)",
            lo=None, sets=("ground", "HEIGHT"), core="ground",
            cli_help="A ground plane at world Z = X, which occludes as an endless floor mesh would "
                     "(instead of --ground's, at each object's lowest point)",
            ui={"soft_min": -100.0, "soft_max": 100.0, "subtype": "DISTANCE", "unit": "LENGTH"}),
    Setting("quantity", "flags", ("AO",), "Quantity",
            "What to bake: ambient occlusion into \"{object}_AO\", thickness into \"{object}_Thickness\" "
            "(rays into the mesh up to Distance: black is thin, white thick), or both (shift-click)",
            cli_help="What to bake: ambient occlusion into \"{object}_AO\", thickness into \"{object}_Thickness\" "
                     "(rays into the mesh up to --max-distance: black is thin, white thick), or both "
                     "(--quantity ao thickness)", core="quantity", items=(
                ("AO", "AO", "Ambient occlusion, into \"{object}_AO\""),
                ("THICKNESS", "Thickness", "How thick the mesh is behind each point (black thin, white thick), "
                                           "into \"{object}_Thickness\"; only the object itself counts"))),
    Setting("uv_map", "str", "", "UV Map", "UV map to bake into; empty for each mesh's active render UV map",
            targets=("image", "udim", "bent")),
    Setting("margin", "int", 16, "Margin", "Extend the baked islands by this many pixels, against seams",
            hi=request.MAX_RESOLUTION, targets=("image", "udim", "bent"), core="margin",
            ui={"soft_max": 64, "subtype": "PIXEL"}),
    Setting("fix_seams", "bool", True, "Fix Seams",
            "After the bake, adjust the texels along UV seams (and the margin beside them) so that both sides "
            "of every seam look the same under Linear interpolation, each texel by as much as its own noise "
            "allows; creases, where the shading changes anyway, are left as they are. Costs a few percent of "
            "the bake", targets=("image", "udim"), core="fix_seams"),
    Setting("image_name", "str", "", "Image",
            'Image to bake into; empty for "{object}_AO"; {object} is replaced by the object name. An '
            "existing image is reused, resized to the bake's size; files are named after it, made safe",
            targets=("image", "udim", "vertex")),
    Setting("images", "enum", "OWN", "Images",
            "Which image each object bakes into: its own, one image for all of them (a texture atlas), or its "
            "materials' image as Cycles' bake finds it", items=(
                ("OWN", "One per Object", 'Each object into its own image ("<object>_AO", or the Image name)'),
                ("ATLAS", "One for All",
                 "Every object into one image, the Atlas name: a texture atlas, each object over its own part of "
                 "the UV square, occluding the others"),
                ("NODE", "Node Image",
                 "Into the image of each object's materials' active Image Texture node, as Cycles' bake finds it; "
                 "objects sharing an image bake into it together. It writes into whatever image that node "
                 "shows, so it is never the default")), targets=("image",)),
    Setting("atlas", "str", "Atlas", "Atlas",
            "The image every object bakes into with Images set to One for All (its files: <name>.png, ...). An "
            "existing image keeps its size, depth and colour space, and the texels of objects not baked now",
            targets=("image",), sets=("images", "ATLAS"),
            cli_help="The image every object bakes into; giving it sets --images atlas (its files: <name>.png, "
                     "...). An existing image keeps its size, depth and colour space, and the texels of objects "
                     "not baked now"),
    Setting("id_map", "bool", False, "ID Map",
            'With several objects in one image, also the image "<image>_ID": each object\'s texels (and its '
            "margin) in a colour of its own, black elsewhere, a mask per object for texturing",
            targets=("image",)),
    Setting("channel", "enum", "NONE", "Channel",
            "Write the AO into one channel of an existing image (Into) and leave its other channels as they "
            "are, e.g. red of a glTF occlusion-roughness-metallic texture", items=(
                ("NONE", "Own Image", "Bake into the object's own image"),
                ("R", "Red", "The red channel of the Into image"),
                ("G", "Green", "The green channel of the Into image"),
                ("B", "Blue", "The blue channel of the Into image"),
                ("A", "Alpha", "The alpha channel of the Into image")), targets=("image",)),
    Setting("into", "image", "", "Into", "The existing image whose Channel receives the AO", targets=("image",)),
    Setting("float_buffer", "bool", True, "32-bit Float",
            "Bake into a float image (else 8-bit); files get 16-bit PNG or float EXR/TIFF when on",
            key=None, targets=("image", "udim", "vertex")),
    Setting("save_to_file", "bool", False, "Save to File", "Also write each baked image to a file", key=None,
            targets=("image", "udim", "bent")),
    Setting("file_format", "enum", "PNG", "Format", "Format of the saved files", key=None, items=(
        ("PNG", "PNG", "8-bit PNG (16-bit with 32-bit Float on)"),
        ("OPEN_EXR", "OpenEXR", "Half-float EXR (float with 32-bit Float on)"),
        ("TIFF", "TIFF", "8-bit TIFF (float with 32-bit Float on)")), targets=("image", "udim", "bent")),
    Setting("output_dir", "str", "//", "Folder",
            'Folder for the files ("//" is the .blend file\'s folder), created if missing. A folder that '
            "cannot be written is refused before baking; if a file fails to write after the bake, the image "
            "in Blender keeps the bake and any file already on disk is left as it was", key=None,
            targets=("image", "udim", "bent"), ui={"subtype": "DIR_PATH", "blend_relative": True}),
    Setting("link_to_file", "bool", True, "Link Image to File",
            "After the file is saved, the image in Blender loads from it, as after Image > Save As: the .blend "
            "file stays small and needs the file beside it. Off, or without Save to File, the image's pixels "
            "are packed into the .blend file", key=None, targets=("image", "udim", "bent")),
    Setting("seed", "int", 0, "Seed", "Seed of the random scrambling; the same seed gives the same image",
            core="seed", ui={"max": (1 << 31) - 1}),
    Setting("threads", "int", 0, "Threads",
            "Threads of each process that bakes; 0 uses the add-on preferences' default (all cores). With "
            "Processes 0, as many processes bake as the cores hold at this many threads each (on 2 cores, "
            "Threads 2 bakes in Blender's own process)",
            cli_help="Threads of each process that bakes; 0: all cores. With --processes 0, as many processes "
                     "bake as the cores hold at this many threads each (on 2 cores, --threads 2 bakes in this "
                     "process)",
            lo=0, hi=MAX_THREADS, zero="every core", core="threads", ui={"soft_max": 256}),
    Setting("processes", "int", 0, "Processes",
            "Worker processes the bake's tiles are baked in, each with its own copy of the scene; 1 bakes in "
            "Blender's own process on threads. 0, with Threads 0, bakes where this machine is predicted to "
            "finish sooner: on Blender's threads, which share one Python, or in as many worker processes as "
            "the cores and the memory hold, which each set up the scene again and must start first unless "
            "they are running; the summary says which and why. The image is the same either way",
            cli_help="Worker processes the bake's tiles are baked in, each with its own copy of the scene; 1 "
                     "bakes in this process on threads. 0, with --threads 0, bakes where this machine is "
                     "predicted to finish sooner: on this process's threads, which share one Python, or in as "
                     "many worker processes as the cores and the memory hold, which each set up the scene again "
                     "and must start first unless they are running (--summary-json says which and why). The "
                     "image is the same either way",
            lo=0, hi=MAX_THREADS, zero="threads or processes, whichever is sooner", core="workers", ui={"soft_max": 64}),
    Setting("denoise", "bool", False, "Denoise",
            "Filter the baked AO over the surface, across UV seams, each texel weighed by its own error: much "
            "less noise at few samples (on the bench's Suzanne at 512x512, 16 denoised samples about match 128 raw ones; "
            "less gain on fine detail such as a dense terrain), for about a "
            "third of a 64-sample bake's time more; the error map then shows the denoised map's error",
            targets=("image", "udim", "vertex"), core="denoise"),
    Setting("ignore_backfaces", "bool", False, "Ignore Backfaces", "Rays that hit the back of a face pass through it",
            core="ignore_backfaces"),
    Setting("target", "enum", "IMAGE_TEXTURES", "Target", "Where the AO goes", items=(
        ("IMAGE_TEXTURES", "Image Textures", "Bake into an image per object, over its UV map"),
        ("VERTEX_COLORS", "Color Attributes",
         "Bake into a color attribute of each mesh, one value per vertex or face corner (no UV map needed)"))),
    Setting("attribute_name", "str", "AO", "Attribute",
            "Color attribute to bake into, created if missing (as a float color with 32-bit Float on, else a "
            "byte color); an existing one of another type or domain is refused", key="attribute",
            cli_help="Color attribute to bake into, created if missing (of --attribute-type); an existing one "
                     "of another type or domain is refused",
            targets=("vertex",)),
    Setting("attribute_domain", "enum", "POINT", "Domain", "Where the color attribute stores its values", items=(
        ("POINT", "Vertex", "One value per vertex: the mean of its face corners' values, as Cycles bakes it"),
        ("CORNER", "Face Corner", "One value per face corner (hard edges keep their faces' shading apart)")),
        key="domain", targets=("vertex",)),
    Setting("use_udim", "bool", False, "UDIM Tiles",
            "Bake every UDIM tile the UV map touches (1001 for UVs in [0, 1], 1002 to the right, 1011 above, "
            "...) into one tiled image, each tile of the bake's size; an existing tiled image is filled tile by "
            "tile, and saved files are named <image>.<tile>.<ext>", key="udim", targets=("udim",)),
    Setting("bent_normals", "bool", False, "Bent Normals",
            "Also bake each texel's mean unoccluded direction into \"{object}_BentNormal\" (RGB = n / 2 + 1/2, "
            "Blender's normal map convention), from the same rays", targets=("image", "udim"), core="bent_normals"),
    Setting("bent_space", "enum", "TANGENT", "Space", "Space of the bent normal map", items=(
        ("TANGENT", "Tangent", "Tangent space of the bake's UV map (MikkTSpace, as Blender's normal bake)"),
        ("OBJECT", "Object", "Object space")), targets=("bent",)),
    Setting("error_map", "bool", False, "Error Map",
            "Also keep how far each texel's AO may be off (its standard error) in the image \"<image>_stderr\", "
            "and in <file>_stderr.exr with Save to File. The error holds for every sampler: texels then draw "
            "two independent sample sets, about 1.2 times the noise of one at the same samples",
            cli_help="Also write how far each texel's AO may be off (its standard error) into "
                     "<image>_stderr.exr. The error holds for every sampler: texels then draw two independent "
                     "sample sets, about 1.2 times the noise of one at the same samples",
            key="stderr", targets=("image", "udim")),
    Setting("use_selected_to_active", "bool", False, "Selected to Active",
            "Bake the ambient occlusion of the selected objects onto the active object's UV map, into "
            "<active>_AO (the active object is the low-poly, the other selected objects the high-poly)",
            key="selected_to_active", targets=("selected_to_active",)),
    Setting("cage_extrusion", "float", 0.0, "Cage Extrusion",
            "Inflate the active object by the specified distance for baking. This helps matching to points "
            "nearer to the outside of the selected object meshes. 0 measures it from the meshes: how far the "
            "high-poly lies outside the low-poly along its normals", lo=0.0, key="extrusion", core="extrusion",
            targets=("selected_to_active",),
            ui={"soft_max": 1.0, "step": 1, "precision": 3, "subtype": "DISTANCE", "unit": "LENGTH"}),
    Setting("max_ray_distance", "distance", 0.0, "Max Ray Distance",
            "The maximum ray distance for matching points between the active and selected objects. If zero, "
            "there is no limit", targets=("selected_to_active",), core="max_ray_distance",
            ui={"soft_max": 1.0, "step": 1, "precision": 3, "subtype": "DISTANCE", "unit": "LENGTH"}),
    Setting("use_cage", "bool", False, "Cage", "Cast rays to active object from a cage", key=None,
            targets=("selected_to_active",)),
    Setting("cage_object", "object", "", "Cage Object",
            "Object to use as cage instead of calculating the cage from the active object with cage extrusion; "
            "it must be a copy of the active object with its vertices moved", key=None,
            targets=("selected_to_active",)),
)

#: The core's options the add-on sets itself, with why (none of them is a setting).
CORE_INTERNAL = {
    "replicates": "from the settings that use the error (BakeSettings.replicates)",
    "quantities": "from Quantity (several quantities are baked together)",
    "falloff": "not offered: AO here is Cycles' (a hit counts whole)",
    "thickness_distance": "Distance's (max_distance): the core decides it where Distance is unlimited",
    "tiles": "every UDIM tile the UVs touch is baked",
    "empty_ok": "a bake that covers no texel is an error",
    "merge": "the core's default",
    "tile_size": "chosen by the core",
    "chunk_rays": "chosen by the core",
    "constant_answer": "benchmarks only",
}
# A core option's kinds of bake -> the settings' targets.
_TARGETS = {"image": "image", "udim": "udim", "corners": "vertex"}
# A core option's kind -> the kind of the setting made of it (other kinds need a setting of their own).
_KINDS = {"int": "int", "float": "float", "distance": "distance", "bool": "bool", "choice": "enum"}


def _from_core(setting):
    """``setting`` with the limits of the core option it gives where it sets none."""
    option = request.BY_NAME[setting.core] if setting.core else None
    if option is None or setting.kind not in ("int", "float", "distance"):
        return setting
    return dataclasses.replace(setting, lo=option.lo if setting.lo is None else setting.lo,
                               hi=option.hi if setting.hi is None else setting.hi)


def setting_of(option):
    """The setting of a core option that no setting of the add-on maps: its name, a label and help
    from its name and meaning, its default, limits and choices (an enum of the choices in capitals)."""
    kind = _KINDS.get(option.kind)
    if kind is None:
        raise AssertionError(f"the core's option {option.name!r} (kind {option.kind!r}) needs a setting in "
                             "mc_ao.schema that gives it, or a reason in CORE_INTERNAL")
    items = tuple((c.upper(), c.replace("_", " ").title(), c) for c in option.choices)
    default = option.default.upper() if kind == "enum" else option.default
    targets = tuple(dict.fromkeys(_TARGETS[k] for k in option.kinds)) if set(option.kinds) != set(request.KINDS) \
        else ("all",)
    return Setting(option.name, kind, default, option.name.replace("_", " ").title(),
                   option.meaning[:1].upper() + option.meaning[1:], lo=option.lo, hi=option.hi, items=items,
                   targets=targets, core=option.name)


_MAPPED = {s.core for s in SETTINGS if s.core}
#: The core's options that became settings of their own (setting_of), in the core's order.
FROM_CORE = tuple(setting_of(o) for o in request.OPTIONS if o.name not in _MAPPED and o.name not in CORE_INTERNAL)
SETTINGS = tuple(_from_core(s) for s in SETTINGS) + FROM_CORE

BY_NAME = {s.name: s for s in SETTINGS}
BY_KEY = {s.option_key: s for s in SETTINGS if s.option_key is not None}

# --format choice -> Blender's file format name (mc_ao.settings.FILE_FORMATS)
FORMATS = {"png": "PNG", "exr": "OPEN_EXR", "tif": "TIFF", "ply": "PLY"}
# --bits choice -> core.files.imageio's bits
BITS = {"8": 8, "16": 16, "half": "half", "float": "float"}


@dataclass(frozen=True)
class Option:
    """One of the script's own options, not a setting of the bake: what to bake, where files go.

    key : the option's dest (``--match-suffix`` is ``match_suffix``) and its manifest key.
    shape : "value", "value?" (a value, or the option alone: ``--cage``), "list" (one or more),
        "pair" (two values) or "flag" (given or not).
    kind : "str", "path" or "size" (N or WxH).
    section : where the script's help lists it: "files" (before the settings), "selected_to_active"
        (with those settings) or "run" (after them).
    batch : True for a manifest key; False for an option the batch sets for each task; text: why a
        manifest cannot set it.
    sets : the settings that the option gives (how the script names them in messages).
    """

    key: str
    help: str
    shape: str = "value"
    kind: str = "str"
    default: object = None
    choices: tuple = ()
    metavar: object = None
    short: str = ""
    section: str = "files"
    batch: object = True
    sets: tuple = ()

    @property
    def option(self):
        return "--" + self.key.replace("_", "-")


OPTIONS = (
    Option("objects", "mesh objects to bake (default: the selected ones with a UV map, else every mesh with a UV "
           "map in the view layer)", shape="list", metavar="NAME"),
    Option("output", "output folder, created if missing (default: out)", kind="path", default="out", short="-o",
           batch=False),
    Option("format", "file formats to write, one file each (default: png; ply for --target vertex-colors)",
           shape="list", choices=tuple(sorted(FORMATS))),
    Option("bits", "sample type of the files: png 8|16, exr half|float, tif 8|16|float (default: 8-bit PNG and "
           "TIFF, half EXR)", choices=tuple(sorted(BITS))),
    Option("resolution", "image size, N or WxH (default: 1024)", kind="size", default=(1024, 1024),
           metavar="N|WxH", sets=("resolution", "height")),
    Option("attribute_type", "type of a new color attribute: float (linear) or byte (sRGB-encoded, as Blender "
           "stores byte colors) (default: float)", default="float", choices=("float", "byte"),
           sets=("float_buffer",)),
    Option("save", "with --target vertex-colors: save the .blend file with the baked color attributes to PATH "
           "(atomically; never the input file unless --overwrite-input is given)", kind="path",
           metavar="PATH.blend", batch="every task would save its .blend file to that one path; a batch of "
           "--target vertex-colors writes each object's .ply file into its task's folder"),
    Option("overwrite_input", "allow --save to replace the .blend file the bake read", shape="flag",
           batch="the batch never saves .blend files"),
    Option("active", "the low-poly to bake onto (default: the file's active object)", metavar="NAME",
           section="selected_to_active"),
    Option("cage", "cast the rays from a cage (Cycles' Cage): alone, the low-poly extruded along its smooth "
           "vertex normals; with NAME, that object, a copy of the low-poly with its vertices moved outwards (the "
           "extrusion is then not used)", shape="value?", metavar="NAME", section="selected_to_active",
           sets=("use_cage", "cage_object")),
    Option("match_suffix", "bake each object named <base>HIGH onto <base>LOW (e.g. _high _low: Chair_high onto "
           "Chair_low), one image per low-poly; implies --selected-to-active", shape="pair",
           metavar=("HIGH", "LOW"), section="selected_to_active"),
    Option("match_collections", "bake each low-poly that --objects names from the other objects of its own "
           "collection (a collection per asset: Chair holds Chair_low and the high-poly parts), every low-poly "
           "with its own high-poly objects; implies --selected-to-active", shape="flag",
           section="selected_to_active"),
    Option("summary_json", "write a JSON record of the run (settings, each object's status, time, rays and "
           "files) to PATH at the end, whatever the exit status", kind="path", metavar="PATH", section="run",
           batch=False),
    Option("quiet", "no progress", shape="flag", short="-q", section="run", batch=False),
)
OPTION_BY_KEY = {o.key: o for o in OPTIONS}
# A setting without an option of its own: the option that gives it.
_GIVEN_BY = {name: o for o in OPTIONS for name in o.sets}


def manifest_keys():
    """The keys a batch manifest may set: ``{key: (its option, its shape)}`` ("value", "value?", "list",
    "pair", "flag", "switch": a setting that is on unless --no-<option>), every setting's with an option
    and the script's own that a task may take."""
    keys = {}
    for setting in SETTINGS:
        if setting.option_key is None:
            continue
        if setting.kind == "bool" and setting.default is True:
            shape = "switch"
        elif setting.kind == "bool" or setting.flag is not None:
            shape = "flag"
        elif setting.kind in ("flags", "collections"):
            shape = "list"
        else:
            shape = "value"
        keys[setting.option_key] = (setting.option, shape)
    for option in OPTIONS:
        if option.batch is True:
            keys[option.key] = (option.option, option.shape)
    return keys


def label_of(name, choice=None):
    """How the panel names a setting (its label), or one of an enum's choices (the item's name)."""
    setting = BY_NAME.get(name)
    if setting is None:
        return option_of(name, choice)
    if choice is None:
        return setting.label
    return next((item[1] for item in setting.items if item[0] == choice), choice)


def option_of(name, choice=None):
    """How the script names a setting or one of its own options (``--udim``, ``--resolution`` for the
    height too), or one of an enum's choices (``vertex-colors``)."""
    if choice is not None:
        return cli_value(choice)
    setting = BY_NAME.get(name)
    if setting is not None and setting.option is not None:
        return setting.option
    option = _GIVEN_BY.get(name) or OPTION_BY_KEY.get(name)
    return option.option if option is not None else name


def unlimited(distance):
    """True when a distance setting means "no limit": 0 or infinity."""
    return distance == 0 or distance == math.inf


def limit(setting):
    """``setting.hi`` (a number, the core's where the setting gives a core option), or None."""
    return setting.hi


def _number(value):
    if isinstance(value, bool):
        return None
    try:
        return float(value)
    except (TypeError, ValueError):
        return None


def _problem(setting, value):
    """What is wrong with one setting's value (text saying what is allowed), or None."""
    kind = setting.kind
    if kind == "int":
        if isinstance(value, bool) or not isinstance(value, int) and not hasattr(value, "__index__"):
            return f"must be a whole number, not {value!r}"
        lo, hi = setting.lo, limit(setting)
        value = int(value)
        if value < lo or (hi is not None and value > hi):
            span = f"at least {lo}" if hi is None else f"from {lo} to {hi}"
            zero = f" (0 = {setting.zero})" if setting.zero else ""
            return f"must be {span}{zero}, not {value}"
        return None
    if kind == "float":
        number = _number(value)
        if setting.lo is None:
            return None if number is not None and math.isfinite(number) else f"must be a finite number, not {value!r}"
        if number is None or not math.isfinite(number) or number < setting.lo:
            what = f"a finite number >= 0 (0 = {setting.zero})" if setting.zero else "a finite distance >= 0"
            return f"must be {what}, not {value!r}"
        return None
    if kind == "distance":
        number = _number(value)
        if number is None or not number >= 0:  # NaN fails too; inf means no limit
            return f"must be a distance >= 0 (0 or inf = unlimited), not {value!r}"
        return None
    if kind == "enum":
        if value not in setting.identifiers:
            return f"must be one of {', '.join(setting.identifiers)}, not {value!r}"
        return None
    if kind == "bool":
        return None if isinstance(value, bool) else f"must be true or false, not {value!r}"
    if kind in ("str", "object", "image"):
        return None if isinstance(value, str) else f"must be text, not {value!r}"
    if kind == "flags":
        values = (value,) if isinstance(value, str) else tuple(value)
        wrong = [v for v in values if v not in setting.identifiers]
        if wrong or not values or len(set(values)) != len(values):
            return f"must be one or more of {', '.join(setting.identifiers)}, each once, not {value!r}"
        return None
    if kind == "collections":
        values = (value,) if isinstance(value, str) else tuple(value)
        if not all(isinstance(v, str) and v for v in values):
            return f"must be collection names, not {value!r}"
        return None
    raise AssertionError(f"unknown kind {kind!r}")


def problems(settings, naming=label_of, *, script=False):
    """Every setting of ``settings`` (a BakeSettings) checked against its schema entry, and the rules
    between settings (mc_ao.rules.RULES): ``[(name, message)]``, empty when it can bake. Each message
    follows its setting's name as ``naming`` writes it (:func:`label_of`, the panel's; :func:`option_of`,
    the script's), and writes the other settings it names the same way. ``script``: ``settings`` also
    holds the script's own options (mc_ao.settings.from_options) and their rules are checked too."""
    out = []
    for setting in SETTINGS:
        problem = _problem(setting, getattr(settings, setting.name))
        if problem is not None:
            out.append((setting.name, problem))
    return out + rules.broken(settings, naming, script=script)
