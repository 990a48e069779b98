"""Bake settings as plain values (no bpy), shared by the operator (from scene.mc_ao), the script and
the batch. The fields, their types and defaults are mc_ao.schema's settings, in its order;
:func:`from_options` makes them from the script's options (or a manifest's), every value and rule
checked."""

import dataclasses
import hashlib
import os
from types import SimpleNamespace

from . import corelink, schema
from .schema import BY_NAME, FROM_CORE, OPTIONS, SETTINGS, unlimited

_TYPES = {"int": int, "float": float, "distance": float, "bool": bool, "enum": str, "str": str, "object": str,
          "image": str, "collections": tuple, "flags": tuple}


def _identifiers(name):
    return BY_NAME[name].identifiers


# Enum identifiers (the scene properties' items; the core's names are their lower case).
SOURCES = {i: i.lower() for i in _identifiers("source")}
DISTRIBUTIONS = {i: i.lower() for i in _identifiers("distribution")}
OCCLUDERS = _identifiers("occluders")
TARGETS = _identifiers("target")  # named as Cycles names them (scene.render.bake.target)
DOMAINS = _identifiers("attribute_domain")
BENT_SPACES = _identifiers("bent_space")
GROUNDS = _identifiers("ground")
QUANTITIES = {i: i.lower() for i in _identifiers("quantity")}  # identifier -> core.bake_ao's quantity
# file format -> (extension, bits for an 8-bit image, bits for a float image), as core.files.imageio takes them
FILE_FORMATS = {
    "PNG": (".png", 8, 16),
    "OPEN_EXR": (".exr", "half", "float"),
    "TIFF": (".tif", 8, "float"),
    "PLY": (".ply", None, None),  # per-vertex AO of a colour-attribute bake (core.files.plyio), no bit depth
}


def _vertex(v):
    return v.target == "VERTEX_COLORS"


#: The settings the panel greys out, and when (a condition on a BakeSettings). A greyed-out setting
#: has no effect: what the operator bakes takes it at its default (BakeSettings.in_effect), so a value
#: the panel shows as inactive is neither used nor refused (Channel back to Own Image with an Into
#: image still set bakes). The panel greys each out by the same condition (mc_ao.panel). The script
#: and the batch take every option as given.
GREYED = {
    "min_samples": lambda v: not v.target_error > 0,
    "bent_space": lambda v: not v.bent_normals or _vertex(v),
    "use_cage": lambda v: not v.use_selected_to_active,
    "cage_object": lambda v: not (v.use_selected_to_active and v.use_cage),
    "cage_extrusion": lambda v: not v.use_selected_to_active or (v.use_cage and bool(v.cage_object)),
    "max_ray_distance": lambda v: not v.use_selected_to_active,
    "occluders": lambda v: v.only_local,
    "occluder_collections": lambda v: v.only_local,
    "exclude_collections": lambda v: v.only_local,
    "ground_height": lambda v: v.ground != "HEIGHT",
    # the Image section: a color-attribute bake has no image
    "resolution": _vertex, "height": _vertex, "margin": _vertex, "uv_map": _vertex,
    "error_map": _vertex, "channel": _vertex, "images": _vertex, "fix_seams": _vertex,
    # which image: the Image name for one image per object, the Atlas name for one for all
    "image_name": lambda v: _vertex(v) or v.images != "OWN",
    "atlas": lambda v: _vertex(v) or v.images != "ATLAS",
    "id_map": lambda v: _vertex(v) or v.images == "OWN",
    "into": lambda v: _vertex(v) or v.channel == "NONE",
    # Save to File's section, closed by its checkbox
    "file_format": lambda v: not v.save_to_file, "output_dir": lambda v: not v.save_to_file,
    "link_to_file": lambda v: not v.save_to_file,
}


def bake_kind(v):
    """The core's kind of the bake of settings ``v``: "corners" (a colour attribute), "udim" or "image"."""
    return "corners" if _vertex(v) else "udim" if v.use_udim else "image"


# The core's options that are settings by themselves (mc_ao.schema.FROM_CORE): greyed out where the bake's
# kind does not take them, as the core call leaves them out there (mc_ao.baking.core_bake).
GREYED.update({s.name: (lambda v, kinds=schema.request.BY_NAME[s.core].kinds: bake_kind(v) not in kinds)
               for s in FROM_CORE if set(schema.request.BY_NAME[s.core].kinds) != set(schema.request.KINDS)})


class _BakeSettingsMethods:
    """What a BakeSettings does with its values; its fields come from mc_ao.schema (see below)."""

    def greyed(self, name):
        """Whether the panel greys setting ``name`` out with these values (it then has no effect)."""
        condition = GREYED.get(name)
        return bool(condition and condition(self))

    def in_effect(self):
        """These settings with every greyed-out one at its default: what the panel shows as active."""
        defaults = {name: BY_NAME[name].default for name in GREYED if self.greyed(name)}
        for name in ("cage_object", "into"):  # pointers: the default is "no datablock"
            if name in defaults:
                defaults[name] = ""
        return dataclasses.replace(self, **defaults) if defaults else self

    @classmethod
    def from_properties(cls, props, **overrides):
        """Copy the values of a property group (scene.mc_ao) or any object with the same attributes.

        An object pointer (``cage_object``) becomes the object's name ("" for none).
        """
        values = {f.name: getattr(props, f.name) for f in dataclasses.fields(cls)}
        for name in ("cage_object", "into"):  # pointers on the scene: the datablock's name
            value = values.get(name)
            if value is None:
                values[name] = ""
            elif not isinstance(value, str):
                values[name] = value.name
        for setting in SETTINGS:
            value = values.get(setting.name)
            if setting.kind == "collections" and not isinstance(value, (tuple, str)):
                # scene.mc_ao's list of collection pointers: the names of those that are set
                values[setting.name] = tuple(item.collection.name for item in value
                                             if getattr(item, "collection", None) is not None)
            elif setting.kind == "flags" and not isinstance(value, tuple):
                values[setting.name] = tuple(i for i in setting.identifiers if i in value)
        values.update(overrides)
        return cls(**values)

    @property
    def size(self):
        """(width, height) of the image in pixels."""
        return self.resolution, self.height or self.resolution

    def stderr_image_name_for(self, object_name, max_bytes=None):
        """The name of the image the standard error of ``object_name``'s bake goes into (with
        ``error_map``): its AO image's name + "_stderr", fitted to ``max_bytes`` the same way."""
        return self.image_name_for(object_name, max_bytes, suffix="_stderr")

    def image_name_for(self, object_name, max_bytes=None, suffix=""):
        """The name of the image that ``object_name`` bakes into: "<object>_AO" or the Image setting.

        max_bytes: the longest name the image can have, in bytes of UTF-8 (Blender's ID names: 63
        up to 4.4, 255 from 5.0; mc_ao.baking.id_name_max_bytes()). Blender would cut a longer name
        at its end: the image would lose "_AO", and two long object names that differ only near
        their end would bake into one image. So the object's part is shortened instead and gets 8
        hex digits of a hash of the whole object name ("<start of name>-1a2b3c4d_AO"): the same
        object always gets the same image, different objects different ones. This is not a file
        name: files get theirs from mc_ao.filewriter.output_files().
        """
        if getattr(self, "images", "OWN") == "ATLAS":  # one image for every object
            return self.atlas_image_name(max_bytes, suffix)
        template = (self.image_name or "{object}_AO") + suffix
        name = template.replace("{object}", object_name)
        if max_bytes is None or len(name.encode("utf-8", "surrogatepass")) <= max_bytes:
            return name
        tag = "-" + hashlib.sha256(object_name.encode("utf-8", "surrogatepass")).hexdigest()[:8]
        count = template.count("{object}")
        room = (max_bytes - len(template.replace("{object}", "").encode("utf-8"))) // max(count, 1) - len(tag)
        if count and room > 0:
            return template.replace("{object}", _clip_utf8(object_name, room) + tag)
        return _clip_utf8(name, max_bytes - len(tag)) + tag  # the template's own text is too long

    def atlas_image_name(self, max_bytes=None, suffix=""):
        """The image of One for All (the Atlas setting) + ``suffix``, cut to ``max_bytes`` at a character."""
        name = str(self.atlas).strip() + suffix
        return name if max_bytes is None else _clip_utf8(name, max_bytes)

    @property
    def vertex_colors(self):
        """Whether the bake goes into colour attributes (no images, no UV map needed)."""
        return self.target == "VERTEX_COLORS"

    @property
    def quantities(self):
        """core.bake_ao's quantities of this bake, in the schema's order: ('ao',), ('thickness',) or both."""
        chosen = (self.quantity,) if isinstance(self.quantity, str) else self.quantity
        return tuple(q for i, q in QUANTITIES.items() if i in chosen)

    def ground_value(self):
        """core.bake_ao's ground: None (off), 'auto' (each object's lowest point) or a height."""
        return {"OFF": None, "AUTO": "auto"}.get(self.ground, float(self.ground_height))

    def quantity_image_name_for(self, object_name, quantity, max_bytes=None, suffix="", root=False):
        """The image of ``object_name``'s bake of ``quantity`` (core's name): image_name_for() for 'ao',
        "<object>_Thickness" for 'thickness', made to fit the same way; ``suffix`` as image_name_for's.
        ``root``: ``object_name`` is the name the images of a shared image's bake start from (its AO
        image's: "Atlas" gives "Atlas_Thickness", "Atlas_stderr")."""
        if root:
            plain = dataclasses.replace(self, image_name="{object}" if quantity == "ao" else "{object}_" +
                                        quantity.capitalize(), images="OWN")
            return plain.image_name_for(object_name, max_bytes, suffix)
        if quantity == "ao":
            return self.image_name_for(object_name, max_bytes, suffix)
        template = "{object}_" + quantity.capitalize()
        return dataclasses.replace(self, image_name=template, images="OWN").image_name_for(object_name, max_bytes,
                                                                                          suffix)

    def bent_image_name_for(self, object_name, max_bytes=None):
        """The image of ``object_name``'s bent normals: "<object>_BentNormal", made to fit as
        image_name_for() makes the AO image's name fit."""
        return dataclasses.replace(self, image_name="{object}_BentNormal", images="OWN").image_name_for(object_name,
                                                                                                      max_bytes)

    @property
    def replicates(self):
        """Independent randomisations per texel (core.bake_ao's ``replicates``): 2 where the bake's
        error is used (adaptive sampling stops on it, the error map shows it, the denoiser weighs each texel
        by it), for an error estimate
        that holds for every sample source; else 1, the least noise for the rays (measured: Sobol'
        1.16-1.20 times the RMSE at equal rays with 2)."""
        return 2 if self.error_map or self.target_error > 0 or self.denoise else 1

    @property
    def file_bits(self):
        """The bit depth core.files.imageio writes the chosen file format with, following the image's depth."""
        _, bits8, bits_float = FILE_FORMATS[self.file_format]
        return bits_float if self.float_buffer else bits8

    def bake_kwargs(self, threads=None):
        """The options of the core's bake request (core.base.request.BakeRequest; core.bake_ao's keywords),
        without target and occluders.

        threads: the number of worker threads, None for all cores; it replaces ``self.threads`` so that
        the caller resolves the preferences' default.
        """
        return dict(
            resolution=self.size,
            samples=self.samples,
            min_samples=min(self.min_samples, self.samples),
            target_error=self.target_error,
            # no limit (0 or inf) is inf to the core; anything else goes as it is (the core refuses < 0, NaN)
            max_distance=float("inf") if unlimited(self.max_distance) else self.max_distance,
            distribution=DISTRIBUTIONS[self.distribution],
            source=SOURCES[self.source],
            margin=self.margin,
            seed=self.seed,
            threads=threads,
            ignore_backfaces=self.ignore_backfaces,
            **({"bent_normals": True} if self.bent_normals and not self.vertex_colors else {}),
            replicates=self.replicates,
            # 0: from the cores and the memory (core.execution.executor.auto_workers); the same bits for any count
            workers="auto" if self.processes == 0 else self.processes,
            **({"denoise": True} if self.denoise else {}),
            # image bakes only (a color attribute has no seams); off goes to the core as off
            **({"fix_seams": bool(self.fix_seams)} if not self.vertex_colors else {}),
            # the ground only when on: a bake without one passes what it passed before
            **({"ground": self.ground_value()} if self.ground != "OFF" else {}),
            # the core's options that are settings of their own (mc_ao.schema.FROM_CORE), as they are
            **{s.core: _core_value(s, getattr(self, s.name)) for s in FROM_CORE},
        )


#: Everything one bake needs besides the objects: a frozen dataclass with one field per schema setting.
BakeSettings = dataclasses.make_dataclass(
    "BakeSettings",
    [(s.name, _TYPES[s.kind], dataclasses.field(default=s.default)) for s in SETTINGS],
    bases=(_BakeSettingsMethods,), frozen=True,
)
BakeSettings.__module__ = __name__
BakeSettings.__doc__ = ("Everything one bake needs besides the objects; one field per mc_ao.schema setting "
                        "(the scene.mc_ao properties' names).")


def _core_value(setting, value):
    """A setting's value as its core option takes it (an enum's identifier in lower case: the core's choice)."""
    return value.lower() if setting.kind == "enum" else value


def _clip_utf8(text, limit):
    """The longest start of ``text`` that is at most ``limit`` bytes of UTF-8 (whole characters)."""
    return text.encode("utf-8", "surrogatepass")[:max(limit, 0)].decode("utf-8", "ignore")


def from_options(args):
    """The BakeSettings of the script's options (an argparse namespace of mc_ao.cli.options's parser;
    the batch's manifest too, as the command line of its task), and what is wrong with them: every
    value and every rule (mc_ao.schema.problems with mc_ao.rules' rules of the options), each a
    sentence naming the options. ``args.format`` is the formats chosen (their default filled in)."""
    width, height = args.resolution
    values, problems = schema.from_options(args)
    values.update(
        resolution=width, height=height, float_buffer=args.attribute_type == "float",
        use_selected_to_active=bool(args.selected_to_active or args.match_suffix
                                    or getattr(args, "match_collections", False)),
        use_cage=args.cage is not None, cage_object=args.cage or "",
    )
    settings = BakeSettings(**values)
    # The rules of the options read them beside the settings (paths as text).
    options = {o.key: getattr(args, o.key, None) for o in OPTIONS}
    options.update((key, None if value is None else os.fspath(value)) for key, value in options.items()
                   if value is not None and isinstance(value, os.PathLike))
    both = SimpleNamespace(**{**options, **dataclasses.asdict(settings)})
    for field, message in schema.problems(both, schema.option_of, script=True):
        if field in ("resolution", "height"):  # both from --resolution, each at least 1 already
            message = (f"--resolution must be at most {corelink.load('base.request').MAX_RESOLUTION} a side, not "
                       f"{width}x{height}")
            if message not in problems:
                problems.append(message)
            continue
        problems.append(f"{schema.option_of(field)} {message}")
    return settings, problems
