"""Bent normals: the mean unoccluded direction per texel, encoded as a normal map, in the image
"<object>_BentNormal" and its files (per tile for UDIM)."""

from .maps import MapOutput


class BentNormalsOutput(MapOutput):
    name = "bent_normals"
    what = "bent normals image"
    content = "bent_normal"

    @classmethod
    def applies(cls, settings):
        return settings.bent_normals and not settings.vertex_colors

    def image_name(self, job):
        if getattr(job, "atlas", False):  # a shared image's: "<image>_BentNormal"
            return self.settings.quantity_image_name_for(job.object_name, "ao", self.max_name_bytes(), "_BentNormal",
                                                         root=True)
        return self.settings.bent_image_name_for(job.object_name, self.max_name_bytes())

    def source(self, result):
        from .. import bent

        return bent.encoded(result, self.settings)

    def metadata(self):
        return {"bent_space": self.settings.bent_space.lower()}
