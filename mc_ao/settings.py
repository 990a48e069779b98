"""Bake settings as plain values (no bpy), shared by the operator (from scene.mc_ao) and scripts/bake_ao.py."""

import hashlib
from dataclasses import dataclass, fields

# RNA enum identifier -> core argument; the enum items in properties.py use these keys.
SOURCES = {"SOBOL": "sobol", "STRATIFIED": "stratified", "INDEPENDENT": "independent", "HALTON": "halton"}
DISTRIBUTIONS = {"COSINE": "cosine", "UNIFORM": "uniform"}
OCCLUDERS = ("SELF", "SELECTED", "VISIBLE")
# file format -> (extension, bits for an 8-bit image, bits for a float image), as core.imageio takes them
FILE_FORMATS = {
    "PNG": (".png", 8, 16),
    "OPEN_EXR": (".exr", "half", "float"),
    "TIFF": (".tif", 8, "float"),
}


@dataclass(frozen=True)
class BakeSettings:
    """Everything one bake needs besides the objects; field names match the scene.mc_ao properties."""

    samples: int = 128
    min_samples: int = 16
    target_error: float = 0.0  # 95% CI half-width to stop a texel at; 0 = adaptive sampling off
    resolution: int = 1024  # image width in pixels
    height: int = 0  # image height in pixels; 0 = square
    max_distance: float = 0.0  # in scene units; 0 = unlimited
    source: str = "SOBOL"
    distribution: str = "COSINE"
    occluders: str = "VISIBLE"
    uv_map: str = ""  # "" = the mesh's active render UV map
    margin: int = 16
    image_name: str = ""  # "" = "<object>_AO"; "{object}" in it is replaced by the object's name
    float_buffer: bool = True
    save_to_file: bool = False
    file_format: str = "PNG"
    output_dir: str = "//"
    link_to_file: bool = True  # with save_to_file: the image loads from its saved file, not packed
    seed: int = 0
    threads: int = 0  # 0 = the add-on preferences' default (whose 0 = all cores)
    ignore_backfaces: bool = False
    error_map: bool = False  # also keep each texel's standard error: image "<image>_stderr", file "<stem>_stderr.exr"

    @classmethod
    def from_properties(cls, props, **overrides):
        """Copy the values of a property group (scene.mc_ao) or any object with the same attributes."""
        values = {f.name: getattr(props, f.name) for f in fields(cls)}
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
        name: files get theirs from mc_ao.jobs.output_files().
        """
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

    @property
    def replicates(self):
        """Independent randomisations per texel (core.bake_ao's ``replicates``): 2 where the bake's
        error is used (adaptive sampling stops on it, the error map shows it), for an error estimate
        that holds for every sample source; else 1, the least noise for the rays (measured: Sobol'
        1.16-1.20 times the RMSE at equal rays with 2)."""
        return 2 if self.error_map or self.target_error > 0 else 1

    @property
    def file_bits(self):
        """The bit depth core.imageio writes the chosen file format with, following the image's depth."""
        _, bits8, bits_float = FILE_FORMATS[self.file_format]
        return bits_float if self.float_buffer else bits8

    def bake_kwargs(self, threads=None):
        """Keyword arguments of core.bake_ao (without target and occluders).

        threads: the number of worker threads, None for all cores; it replaces ``self.threads`` so that
        the caller resolves the preferences' default.
        """
        return dict(
            resolution=self.size,
            samples=self.samples,
            min_samples=min(self.min_samples, self.samples),
            target_error=self.target_error,
            # 0 means unlimited; anything else goes to the core as it is (which refuses < 0 and NaN).
            max_distance=float("inf") if self.max_distance == 0 else self.max_distance,
            distribution=DISTRIBUTIONS[self.distribution],
            source=SOURCES[self.source],
            margin=self.margin,
            seed=self.seed,
            threads=threads,
            ignore_backfaces=self.ignore_backfaces,
            replicates=self.replicates,
        )


def _clip_utf8(text, limit):
    """The longest start of ``text`` that is at most ``limit`` bytes of UTF-8 (whole characters)."""
    return text.encode("utf-8", "surrogatepass")[:max(limit, 0)].decode("utf-8", "ignore")
