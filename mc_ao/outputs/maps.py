"""Maps: an output that is an image of the object's UVs, made from one plane of the core's result.

:class:`MapOutput` is every map's steps (check, store, save, keep) for a plain image and for UDIM
tiles alike (:mod:`.udim_tiles` does the tiles); a kind of map says only which plane it writes
(``source(result)``: the AO, its standard error, the encoded bent normals), from which core result
(``quantity``: None for the job's own bake), under which image name (``image_name(job)``) and what its files' metadata calls it
(``content``). A thickness map or a channel-packed image is a subclass in a file of its own, and a
line in mc_ao.outputs.KINDS.
"""

from .. import corelink, filewriter
from ..baking import id_name_max_bytes
from . import udim_tiles
from .base import FileWrite, OutputKind


class MapOutput(OutputKind):
    """An image over the object's UVs (a tiled one for a UDIM bake) and its files."""

    name = "map"
    what = "map"
    #: The files' metadata "content" (core.files.imageio reads it back).
    content = "ao"
    #: The image's float buffer: None for the settings' 32-bit Float, else always this.
    float_image = None
    #: Whether this map's image and files keep the record of a shared image's bake (mc_ao.atlas):
    #: the map of the bake's own quantity.
    keeps_record = False

    # -- what it is ------------------------------------------------------------------------------

    def image_name(self, job):
        """The Blender image (and file stem) of ``job``'s map."""
        return job.image_name

    def max_name_bytes(self):
        """The longest image name this Blender keeps (mc_ao.baking.id_name_max_bytes), None without bpy."""
        try:
            return id_name_max_bytes()
        except ImportError:
            return None

    def source(self, result):
        """The plane of one core result this map holds: (H, W) values or (H, W, 3) colours."""
        return result.ao

    def plane(self, results):
        """The map's plane from ``results`` ({quantity: core result}, one tile's for UDIM). A map
        made of several quantities (a channel-packed image) overrides this instead of source()."""
        return self.source(results[self.quantity])

    def float_buffer(self):
        return self.settings.float_buffer if self.float_image is None else self.float_image

    def metadata(self):
        """What its files' metadata adds to the bake's (the content is added always)."""
        return {}

    # -- files -----------------------------------------------------------------------------------

    def file_names(self, job):
        """The names whose files mc_ao.filewriter.output_files plans for this map (distinct stems over all)."""
        return [self.image_name(job)]

    def targets(self, entry):
        """[(path, file format, bits for core.files.imageio, bits for Blender's writer)] of one planned
        OutputFile of this map."""
        return [(entry.path, entry.file_format, entry.bits, entry.bits)]

    def entries(self, job, files):
        return files.get(self.image_name(job), [])

    def planned(self, job, files):
        record = self.record_path(job, files)
        return [t[0] for entry in self.entries(job, files) for t in self.targets(entry)] + ([record] if record else [])

    def record_path(self, job, files):
        """Where the record of a shared image's bake goes beside its files (the first one's stem), or None."""
        if not (self.keeps_record and getattr(job, "atlas", False)) or self.settings.use_udim:
            return None
        entries = self.entries(job, files)
        if not entries:
            return None
        return corelink.load("files.atlasrecord").sidecar_path(entries[0].path)

    def writes(self, job, results, files, metadata):
        out = []
        record = getattr(results[self.quantity], "record", None)
        path = self.record_path(job, files)
        if path is not None and record is not None:
            out.append(FileWrite(path, lambda target, record=record: record.write_to(target), self.name, planned=path))
        for tile, per_tile in udim_tiles.split(results, self.quantity, self.settings):
            own = udim_tiles.tile_entries(self.entries(job, files), tile)
            result = per_tile[self.quantity]
            meta = dict(getattr(result, "metadata", None) or {}, **metadata,
                        **({} if tile is None else {"udim_tile": tile}), content=self.content, **self.metadata())
            plane = self.plane(per_tile)
            for entry, planned in zip(own, self.entries(job, files)):
                for (path, file_format, bits, blender_bits), (base, *_) in zip(self.targets(entry),
                                                                            self.targets(planned)):
                    out.append(FileWrite(path, _writer(plane, file_format, bits, blender_bits, meta), self.name,
                                         planned=base, tile=tile))
        return out

    # -- Blender -------------------------------------------------------------------------------

    def check(self, job):
        from .. import images

        name = self.image_name(job)
        if self.settings.use_udim:
            w, h = self.settings.size
            udim_tiles.check(name, w, h)
        elif getattr(job, "atlas", False):
            images.check_shared(name)
        else:
            images.check_target(name)

    def store(self, run, job, results):
        from .. import images

        name = self.image_name(job)
        if self.settings.use_udim:
            udim_tiles.store(run, name, {tile: self.plane(per_tile) for tile, per_tile
                                         in udim_tiles.split(results, self.quantity, self.settings)},
                             self.float_buffer())
            return
        plane = self.plane(results)
        h, w = plane.shape[:2]
        if getattr(job, "atlas", False):
            self.store_shared(run, job, name, plane, results[self.quantity])
            return
        run.image(name, w, h, self.float_buffer())
        images.finish_image(name, plane, self.float_buffer())

    def store_shared(self, run, job, name, plane, result):
        """A shared image's map (mc_ao.atlas): a new image as any map's; an existing one keeps its size,
        depth, colour space and every texel the bake did not reach, which the report says."""
        import bpy

        from .. import images

        h, w = plane.shape[:2]
        existed = bpy.data.images.get(name) is not None
        run.image(name, w, h, self.float_buffer())
        if not existed:
            images.finish_image(name, plane, self.float_buffer())
        else:
            image = images.store_shared(name, plane, result.owner >= 0)
            if self.keeps_record:
                report = (result.report or {}).get("atlas") or {}
                others = [n for n in report.get("kept", []) if n not in job.names]
                held = f" and the texels of {', '.join(others)}" if others else ""
                run.report("INFO", f"{job.object_name}: image {name!r} kept its {images.describe(image)}{held}")
        if self.keeps_record and getattr(result, "record", None) is not None:
            images.keep_record(name, result.record.to_bytes())

    def keep(self, run, job, results, saved):
        from . import store

        name = self.image_name(job)
        path = saved[0] if saved else None
        if self.settings.use_udim:
            result = results[self.quantity]
            path = path and udim_tiles.untiled(path, min(result.tiles))
            udim_tiles.keep(run, job, name, result, path)
            return
        store.keep_image(run, job, name, lambda: self.plane(results), self.float_buffer(), path)


def _writer(plane, file_format, bits, blender_bits, metadata):
    """write(target): the plane to ``target``, OpenImageIO where this Python has it, else Blender's writer."""

    def write(target):
        if filewriter.oiio_available():
            corelink.load("files.imageio").write_image(target, plane, bits=bits, metadata=metadata)
        else:
            from .. import images

            images.save_pixels_with_blender(images.rgba(plane), target, file_format, blender_bits)

    return write
