"""The error map: each texel's standard error in the float image "<image>_stderr" and in the file
``<stem>_stderr.exr`` beside the AO's first file (per tile for UDIM)."""

from .maps import MapOutput


class ErrorMapOutput(MapOutput):
    name = "error_map"
    what = "error map"
    content = "stderr"
    float_image = True
    #: Its files are the AO files' standard-error companions (mc_ao.filewriter.OutputFile.stderr_path).
    stderr_file = True
    #: A failure to keep it in Blender is a warning; the AO is kept.
    optional = True

    @classmethod
    def applies(cls, settings):
        return settings.error_map and not settings.vertex_colors

    def image_name(self, job):
        if getattr(job, "atlas", False):  # a shared image's: "<image>_stderr"
            return self.settings.quantity_image_name_for(job.image_name, "ao", self.max_name_bytes(), "_stderr",
                                                         root=True)
        return self.settings.quantity_image_name_for(job.object_name, getattr(job, "quantity", "ao"), self.max_name_bytes(),
                                                     "_stderr")

    def source(self, result):
        return result.stderr

    def file_names(self, job):
        return []

    def entries(self, job, files):
        return files.get(job.image_name, [])

    def targets(self, entry):
        return [(entry.stderr_path, "OPEN_EXR", None, "float")] if entry.stderr_path else []
