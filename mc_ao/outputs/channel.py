"""The map written into one channel (R, G, B or A) of an existing image, the Channel and Into settings:
the image's other channels exactly as they were (glTF's occlusion-roughness-metallic texture keeps the
occlusion in red).

Which map: the object's AO job's own (the Channel setting takes Quantity AO alone, mc_ao.cli and
mc_ao.baking refuse the rest); the map also goes into the object's own image as always. Where:

- Into names a Blender image: its pixels get the map in that channel (core.files.channels.pack_channel),
  snapshot first and put back when the object does not finish; a generated image is then packed into
  the .blend file (else a save would lose it), a file image is left modified (save it to write it).
  With Save to File, a copy of the image's file (its own format, sample types and attributes) with
  the channel replaced goes into the output folder under the file's name (core.files.channels.write_channel);
  an image without a file there is written whole, in the bake's format.
- Into is a file (the script's ``--into PATH``): the copy of that file with the channel replaced goes
  into the output folder under its name; the file itself is never changed (an input of the bake).

The image must be the bake's size and have the channel (mc_ao.baking.channel_problem, before any
work); one object at a time writes into it (two would each replace the whole channel).
"""

import os
import sys

from .base import FileWrite, OutputKind

#: Channel setting -> index in an image's pixels.
INDEX = {"R": 0, "G": 1, "B": 2, "A": 3}


class ChannelOutput(OutputKind):
    name = "channel"
    what = "copy of the Into image"
    quantity = None  # the job's own bake

    def __init__(self, settings):
        super().__init__(settings)
        self.objects = []  # the objects whose map goes into the channel, as checked

    @classmethod
    def applies(cls, settings):
        return settings.channel != "NONE" and not settings.vertex_colors

    # -- which job, which image ----------------------------------------------------------------------

    def mine(self, job):
        """Whether ``job``'s map goes into the channel: the object's first quantity's job."""
        return getattr(job, "quantity", "ao") == self.settings.quantities[0]

    def blender_image(self):
        """The Into image in Blender, or None (Into is a file, or no Blender here)."""
        bpy = sys.modules.get("bpy")  # the add-on and the script run with it imported; a plain Python without
        return None if bpy is None else bpy.data.images.get(self.settings.into)

    def source_file(self):
        """The file whose other channels the written file keeps: Into's own (a file path, or a
        Blender image's file that exists), or None."""
        image = self.blender_image()
        if image is None:
            path = self.settings.into
        elif image.source == "FILE" and image.packed_file is None and image.filepath:
            import bpy

            path = bpy.path.abspath(image.filepath, library=image.library)
        else:
            return None
        path = os.path.normpath(path)
        return path if os.path.isfile(path) else None

    def stem(self):
        """The name its file is planned under (mc_ao.filewriter.output_files): Into's file's stem, or
        the Blender image's name without an extension."""
        source = self.source_file()
        base = os.path.basename(source) if source is not None else self.settings.into
        return os.path.splitext(base)[0] or base

    def file_names(self, job):
        return [self.stem()] if self.mine(job) else []

    def clash_hint(self):
        return (f"the copy of Into {self.settings.into!r} keeps its name; give the object's image another name "
                "(Image Name) or choose another Into")

    def paths(self, job, files):
        """Its paths in the output folder: the planned ones, with Into's file's extension where it has
        a file (the copy keeps its format); one per format otherwise."""
        if not self.mine(job):
            return []
        source = self.source_file()
        out = []
        for entry in files.get(self.stem(), []):
            path = os.fspath(entry.path)
            if source is not None:
                path = os.path.splitext(path)[0] + os.path.splitext(source)[1]
            if path not in [p for p, _ in out]:
                out.append((path, entry))
        return out

    # -- 1. before any work ----------------------------------------------------------------------

    def udim_problem(self):
        if self.settings.use_udim:
            return (f"Channel {self.settings.channel} into {self.settings.into!r} takes a plain image, not UDIM "
                    "tiles; turn UDIM off or set Channel to Own Image")
        return None

    def check(self, job):
        from .. import images, precheck

        if self.settings.into == job.image_name:  # the object's own image would take the whole AO over it
            raise images.ImageError(precheck.own_image_is_into(job.image_name, job.object_name))
        if not self.mine(job):
            return
        problem = self._one_object(job)
        if problem:
            raise images.ImageError(problem)
        if self.udim_problem():
            raise images.ImageError(self.udim_problem())
        image = self.blender_image()
        if image is not None:
            reason = images.unusable_reason(image)
            if reason is not None:
                raise images.ImageError(reason)
            w, h = getattr(job, "size", None) or self.settings.size  # a shared image's bake: its own size
            if tuple(image.size) != (w, h):
                raise images.ImageError(f"image {image.name!r} is {image.size[0]}x{image.size[1]}, not the bake's "
                                        f"{w}x{h}: bake at its size to write into its {self.settings.channel} channel")

    def _one_object(self, job):
        """Why ``job`` cannot write into the Into image (another object already does), or None."""
        if job.object_name not in self.objects:
            self.objects.append(job.object_name)
        if len(self.objects) > 1:
            return (f"{self.objects[0]} and {self.objects[1]} would both write into channel "
                    f"{self.settings.channel} of {self.settings.into!r}, each the whole channel: "
                    "bake one object into it at a time")
        return None

    def planned(self, job, files):
        return [p for p, _ in self.paths(job, files)]

    def check_files(self, job, files):
        problems = super().check_files(job, files)
        if not self.mine(job):
            return problems
        problem = self._one_object(job)
        if problem:
            problems.append(problem)
        if self.udim_problem():
            problems.append(self.udim_problem())
        from .. import filecheck

        source = self.source_file()
        for path in self.planned(job, files):
            if source and filecheck.same_file(path, source):  # by the file it reaches: a linked output folder too
                problems.append(f"{path!r} is the Into image's own file, which the bake does not replace: choose "
                                "another output folder")
        return problems

    # -- 3. into Blender ---------------------------------------------------------------------------

    def store(self, run, job, results):
        if not self.mine(job):
            return
        image = self.blender_image()
        if image is None:
            return
        from .. import corelink, images

        plane = results[None].ao
        h, w = plane.shape
        image = run.image(image.name, w, h, image.is_float)  # snapshot (put back if the object does not finish)
        pixels = images.pixels_of(image)
        try:
            packed = corelink.load("files.channels").pack_channel(pixels, INDEX[self.settings.channel], plane)
        except corelink.load().SettingsError as exc:
            raise images.ImageError(str(exc)) from None
        images.set_pixels(image, packed)

    # -- 4. files ----------------------------------------------------------------------------------

    def writes(self, job, results, files, metadata):
        plane = results[None].ao
        channel, source = self.settings.channel, self.source_file()
        out = []
        for path, entry in self.paths(job, files):
            def write(target, entry=entry):
                from .. import corelink

                io = corelink.load("files.imageio")
                if source is not None:
                    corelink.load("files.channels").write_channel(target, channel, plane, source=source)
                    return
                # No file to keep the other channels of: the Blender image's pixels, the channel packed.
                from .. import images

                pixels = corelink.load("files.channels").pack_channel(images.pixels_of(self.blender_image()), INDEX[channel], plane)
                io.write_image(target, pixels, bits=entry.bits, metadata=dict(metadata, content="packed",
                                                                              channel=channel))

            out.append(FileWrite(path, write, self.name))
        return out

    def keep(self, run, job, results, saved):
        if not self.mine(job):
            return
        image = self.blender_image()
        if image is None:
            return
        from .. import images, undo_images

        if image.source == "GENERATED" or image.packed_file is not None:
            try:
                images.pack(image)  # a generated image's pixels live only in the .blend file
                undo_images.record(image)  # undo and redo show this bake's pixels or the last's
            except images.ImageError as exc:
                run.warn(str(exc))
        else:
            run.warn(f"image {image.name!r} has the map in its {self.settings.channel} channel; save the image "
                     "(Image > Save) to write it to its file")
