"""The ID map of a shared image (Images: One for All, Node Image): "<image>_ID", each object's texels in
a colour of its own (core.geometry.atlas.id_colour: from its name, so it keeps it), black elsewhere."""

from .maps import MapOutput


class IdMapOutput(MapOutput):
    name = "id_map"
    what = "ID map"
    content = "id"
    float_image = False
    optional = True

    @classmethod
    def applies(cls, settings):
        return getattr(settings, "id_map", False) and settings.images != "OWN" and not settings.vertex_colors

    def image_name(self, job):
        return self.settings.quantity_image_name_for(job.object_name, "ao", self.max_name_bytes(), "_ID", root=True)

    def file_names(self, job):
        return [self.image_name(job)] if getattr(job, "quantity", "ao") == self.settings.quantities[0] else []

    def entries(self, job, files):
        return files.get(self.image_name(job), []) if self.file_names(job) else []

    def source(self, result):
        from .. import corelink

        return corelink.load("geometry.atlas").id_map(result.owner, result.targets)

    def store(self, run, job, results):
        """Its own image, replaced whole (it holds nothing but this bake's ID map)."""
        if not self.file_names(job):
            return
        from .. import images

        name = self.image_name(job)
        plane = self.plane(results)
        h, w = plane.shape[:2]
        run.image(name, w, h, False)
        images.finish_image(name, plane, False)

    def keep(self, run, job, results, saved):
        if self.file_names(job):
            super().keep(run, job, results, saved)
