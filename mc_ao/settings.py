"""Bake settings as plain values (no bpy), shared by the operator (from scene.mc_ao) and scripts/bake_ao.py."""

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

    def image_name_for(self, object_name):
        if not self.image_name:
            return f"{object_name}_AO"
        return self.image_name.replace("{object}", object_name)

    def file_name_for(self, object_name):
        return self.image_name_for(object_name) + FILE_FORMATS[self.file_format][0]

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
            max_distance=self.max_distance if self.max_distance > 0 else float("inf"),
            distribution=DISTRIBUTIONS[self.distribution],
            source=SOURCES[self.source],
            margin=self.margin,
            seed=self.seed,
            threads=threads,
            ignore_backfaces=self.ignore_backfaces,
        )
