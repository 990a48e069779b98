"""A colour-attribute bake: the AO per face corner in the mesh's colour attribute, and a PLY file
of the mesh with it (named like its image would be)."""

import os

from .. import corelink, summaries
from ..extract import ExtractError
from .base import FileWrite, OutputKind


class ColorAttributeOutput(OutputKind):
    name = "color_attribute"
    what = "colour attribute's file"
    #: Its files' formats, whatever the Format setting.
    file_formats = [("PLY", None)]

    @classmethod
    def applies(cls, settings):
        return settings.vertex_colors

    def file_names(self, job):
        return [job.image_name]

    def planned(self, job, files):
        return [f.path for f in files.get(job.image_name, [])]

    def store(self, run, job, results):
        import bpy

        from .. import vertex_colors

        obj = bpy.data.objects.get(job.object_name)
        if obj is None:
            raise ExtractError("the object is gone")
        vertex_colors.write_attribute(obj, self.settings, results[self.quantity], job.target.extra)

    def writes(self, job, results, files, metadata):
        from .. import vertex_colors

        result = results[self.quantity]
        ply = vertex_colors.ply_data(result, job.target.extra, self.settings.attribute_domain)
        meta = dict(result.metadata, **metadata, content="ao")

        def write(target):
            corelink.load("files.plyio").write_ply(target, *ply, meta)

        return [FileWrite(os.fspath(f.path), write, self.name) for f in files.get(job.image_name, [])]

    def summarise(self, job, results):
        result = results[self.quantity]
        per, rate = summaries.throughput(result)
        settings = self.settings
        domain = "per vertex" if settings.attribute_domain == "POINT" else "per face corner"
        return (f"{job.object_name}: {len(result.ao)} face corners into color attribute "
                f"{settings.attribute_name!r} ({domain}) in {result.seconds:.2f} s{summaries.parallel_words(result)}, "
                f"{per:.0f} samples per corner, {rate:.2f} M rays/s")
