"""The bake settings on every scene (``scene.mc_ao``) and the add-on preferences."""

import bpy
from bpy.props import BoolProperty, EnumProperty, FloatProperty, IntProperty, PointerProperty, StringProperty

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
    # Issue 14: where the bake goes (Cycles' names), UDIM tiles, bent normals.
    target: EnumProperty(
        name="Target", description="Where the AO goes",
        items=[
            ("IMAGE_TEXTURES", "Image Textures", "Bake into an image per object, over its UV map"),
            ("VERTEX_COLORS", "Color Attributes",
             "Bake into a color attribute of each mesh, one value per vertex or face corner (no UV map needed)"),
        ],
        default=_DEFAULTS.target,
    )
    attribute_name: StringProperty(
        name="Attribute",
        description=(
            "Color attribute to bake into, created if missing (as a float color with 32-bit Float on, "
            "else a byte color); an existing one of another type or domain is refused"
        ),
        default=_DEFAULTS.attribute_name,
    )
    attribute_domain: EnumProperty(
        name="Domain", description="Where the color attribute stores its values",
        items=[
            ("POINT", "Vertex", "One value per vertex: the mean of its face corners' values, as Cycles bakes it"),
            ("CORNER", "Face Corner", "One value per face corner (hard edges keep their faces' shading apart)"),
        ],
        default=_DEFAULTS.attribute_domain,
    )
    use_udim: BoolProperty(
        name="UDIM Tiles",
        description=(
            "Bake every UDIM tile the UV map touches (1001 for UVs in [0, 1], 1002 to the right, 1011 "
            "above, ...) into one tiled image, each tile of the bake's size; an existing tiled image is "
            "filled tile by tile, and saved files are named <image>.<tile>.<ext>"
        ),
        default=_DEFAULTS.use_udim,
    )
    bent_normals: BoolProperty(
        name="Bent Normals",
        description=(
            'Also bake each texel\'s mean unoccluded direction into "<object>_BentNormal" (RGB = n / 2 + 1/2, '
            "Blender's normal map convention), from the same rays"
        ),
        default=_DEFAULTS.bent_normals,
    )
    bent_space: EnumProperty(
        name="Space", description="Space of the bent normal map",
        items=[
            ("TANGENT", "Tangent", "Tangent space of the bake's UV map (MikkTSpace, as Blender's normal bake)"),
            ("OBJECT", "Object", "Object space"),
        ],
        default=_DEFAULTS.bent_space,
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
    # Selected to Active, named and described as Cycles' bake settings (scene.render.bake).
    use_selected_to_active: BoolProperty(
        name="Selected to Active",
        description=(
            "Bake the ambient occlusion of the selected objects onto the active object's UV map, "
            "into <active>_AO (the active object is the low-poly, the other selected objects the high-poly)"
        ),
        default=_DEFAULTS.use_selected_to_active,
    )
    cage_extrusion: FloatProperty(
        name="Cage Extrusion",
        description=(
            "Inflate the active object by the specified distance for baking. This helps matching to points "
            "nearer to the outside of the selected object meshes"
        ),
        default=_DEFAULTS.cage_extrusion, min=0.0, soft_max=1.0, step=1, precision=3,
        subtype="DISTANCE", unit="LENGTH",
    )
    max_ray_distance: FloatProperty(
        name="Max Ray Distance",
        description=(
            "The maximum ray distance for matching points between the active and selected objects. "
            "If zero, there is no limit"
        ),
        default=_DEFAULTS.max_ray_distance, min=0.0, soft_max=1.0, step=1, precision=3,
        subtype="DISTANCE", unit="LENGTH",
    )
    use_cage: BoolProperty(
        name="Cage", description="Cast rays to active object from a cage", default=_DEFAULTS.use_cage,
    )
    cage_object: PointerProperty(
        name="Cage Object",
        description=(
            "Object to use as cage instead of calculating the cage from the active object with cage "
            "extrusion; it must be a copy of the active object with its vertices moved"
        ),
        type=bpy.types.Object,
        poll=lambda _self, obj: obj.type == "MESH",
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
