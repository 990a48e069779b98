"""The bake settings on every scene (``scene.mc_ao``) and the add-on preferences."""

import bpy
from bpy.props import BoolProperty, EnumProperty, FloatProperty, IntProperty, StringProperty

from .settings import BakeSettings

# core.bake.MAX_SAMPLES and MAX_RESOLUTION (the core is not imported at registration: it needs numpy
# and embreex); tests/blender check that they agree.
MAX_SAMPLES = 1 << 20
MAX_RESOLUTION = 65536

_DEFAULTS = BakeSettings()
# Blender 4.5 and later warn about "//" in a path property unless it declares that it supports it;
# older versions do not know the option.
_BLEND_RELATIVE = (
    {"PATH_SUPPORTS_BLEND_RELATIVE"}
    if "is_path_supports_blend_relative" in bpy.types.Property.bl_rna.properties
    else set()
)


class McAoSettings(bpy.types.PropertyGroup):
    """Settings of the AO bake, stored with the scene. Field names match mc_ao.settings.BakeSettings."""

    samples: IntProperty(
        name="Samples", description="Rays per texel (the most, when adaptive sampling stops early)",
        default=_DEFAULTS.samples, min=1, max=MAX_SAMPLES, soft_max=4096,
    )
    min_samples: IntProperty(
        name="Min Samples", description="Rays per texel before adaptive sampling may stop a texel",
        default=_DEFAULTS.min_samples, min=1, max=MAX_SAMPLES, soft_max=1024,
    )
    target_error: FloatProperty(
        name="Noise Threshold",
        description=(
            "Adaptive sampling: stop a texel once its AO is known to within this, 95% of the time "
            "(0.01: +-0.01). Open and fully occluded areas stop at Min Samples, noisy ones take up to "
            "Samples. 0 turns adaptive sampling off"
        ),
        default=_DEFAULTS.target_error, min=0.0, max=1.0, soft_max=0.1, step=0.1, precision=4,
    )
    resolution: IntProperty(
        name="Size",
        description=(
            "Width of the image in pixels. An existing image of another size is resized to this size "
            "(and put back as it was if its bake is cancelled or fails)"
        ),
        default=_DEFAULTS.resolution,
        min=1, max=MAX_RESOLUTION, soft_min=16, soft_max=8192, subtype="PIXEL",
    )
    height: IntProperty(
        name="Height", description="Height of the image in pixels; 0 makes it square",
        default=_DEFAULTS.height, min=0, max=MAX_RESOLUTION, soft_max=8192, subtype="PIXEL",
    )
    max_distance: FloatProperty(
        name="Distance", description="Occluders farther than this do not count; 0 = no limit",
        default=_DEFAULTS.max_distance, min=0.0, soft_max=100.0, subtype="DISTANCE", unit="LENGTH",
    )
    source: EnumProperty(
        name="Sampler", description="Where each texel's sample points come from",
        items=[
            ("SOBOL", "Sobol'", "Owen-scrambled Sobol' points over position and direction (least noise)"),
            ("HALTON", "Halton", "Scrambled Halton points"),
            ("STRATIFIED", "Stratified", "Jittered strata"),
            ("INDEPENDENT", "Independent", "Independent uniform random points"),
        ],
        default=_DEFAULTS.source,
    )
    distribution: EnumProperty(
        name="Directions", description="How ray directions are spread over the hemisphere",
        items=[
            ("COSINE", "Cosine", "Cosine-weighted: no noise on open surfaces"),
            ("UNIFORM", "Uniform", "Uniform over the hemisphere"),
        ],
        default=_DEFAULTS.distribution,
    )
    occluders: EnumProperty(
        name="Occluders", description="What casts occlusion onto the baked objects",
        items=[
            ("SELF", "Object Alone", "Each object occludes only itself"),
            ("SELECTED", "Selected", "The selected objects occlude each other"),
            ("VISIBLE", "All Visible", "Every visible object in the view layer"),
        ],
        default=_DEFAULTS.occluders,
    )
    uv_map: StringProperty(
        name="UV Map", description="UV map to bake into; empty for each mesh's active render UV map",
        default=_DEFAULTS.uv_map,
    )
    margin: IntProperty(
        name="Margin", description="Extend the baked islands by this many pixels, against seams",
        default=_DEFAULTS.margin, min=0, soft_max=64, subtype="PIXEL",
    )
    image_name: StringProperty(
        name="Image",
        description=(
            'Image to bake into; empty for "<object>_AO"; "{object}" is replaced by the object name. '
            "An existing image is reused, resized to the bake's size"
        ),
        default=_DEFAULTS.image_name,
    )
    float_buffer: BoolProperty(
        name="32-bit Float",
        description="Bake into a float image (else 8-bit); files get 16-bit PNG or float EXR/TIFF when on",
        default=_DEFAULTS.float_buffer,
    )
    save_to_file: BoolProperty(
        name="Save to File", description="Also write each baked image to a file", default=_DEFAULTS.save_to_file,
    )
    file_format: EnumProperty(
        name="Format",
        items=[
            ("PNG", "PNG", "8-bit PNG (16-bit with 32-bit Float on)"),
            ("OPEN_EXR", "OpenEXR", "Half-float EXR (float with 32-bit Float on)"),
            ("TIFF", "TIFF", "8-bit TIFF (float with 32-bit Float on)"),
        ],
        default=_DEFAULTS.file_format,
    )
    output_dir: StringProperty(
        name="Folder",
        description=(
            'Folder for the files ("//" is the .blend file\'s folder), created if missing. A folder that '
            "cannot be written is refused before baking; if a file fails to write after the bake, the "
            "image in Blender keeps the bake and any file already on disk is left as it was"
        ),
        default=_DEFAULTS.output_dir, subtype="DIR_PATH", options=_BLEND_RELATIVE,
    )
    link_to_file: BoolProperty(
        name="Link Image to File",
        description=(
            "After the file is saved, the image in Blender loads from it, as after Image > Save As: "
            "the .blend file stays small and needs the file beside it. Off, or without Save to File, "
            "the image's pixels are packed into the .blend file"
        ),
        default=_DEFAULTS.link_to_file,
    )
    seed: IntProperty(
        name="Seed", description="Seed of the random scrambling; the same seed gives the same image",
        default=_DEFAULTS.seed, min=0,
    )
    threads: IntProperty(
        name="Threads", description="Worker threads; 0 uses the add-on preferences' default",
        default=_DEFAULTS.threads, min=0, soft_max=256,
    )
    ignore_backfaces: BoolProperty(
        name="Ignore Backfaces", description="Rays that hit the back of a face pass through it",
        default=_DEFAULTS.ignore_backfaces,
    )
    error_map: BoolProperty(
        name="Error Map",
        description=(
            'Also keep how far each texel\'s AO may be off (its standard error) in the image "<image>_stderr", '
            "and in <file>_stderr.exr with Save to File. The error holds for every sampler: texels then draw "
            "two independent sample sets, about 1.2 times the noise of one at the same samples"
        ),
        default=_DEFAULTS.error_map,
    )


class McAoPreferences(bpy.types.AddonPreferences):
    # register() sets bl_idname to the add-on's module name, which differs between an installed
    # extension (bl_ext.<repo>.mc_ao) and a checkout.
    bl_idname = "mc_ao"

    threads: IntProperty(
        name="Default Threads",
        description="Worker threads of a bake whose Threads setting is 0; 0 uses all cores",
        default=0, min=0, soft_max=256,
    )

    def draw(self, context):
        self.layout.prop(self, "threads")


def default_threads(context):
    """The preferences' thread count, or 0 (all cores) when the add-on is not enabled as an add-on."""
    addon = context.preferences.addons.get(McAoPreferences.bl_idname)
    return addon.preferences.threads if addon is not None and addon.preferences is not None else 0


def resolve_threads(context, settings):
    """Thread count for core.bake_ao: the scene's, else the preferences', else None (all cores)."""
    return settings.threads or default_threads(context) or None
