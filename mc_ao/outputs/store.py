"""What the output kinds store into Blender with: images prepared once per object with a snapshot
(put back when the object does not finish), and a finished image kept for good (its saved file, or
its pixels packed into the .blend file). Needs bpy when used, not to import."""


class Store:
    """The Blender side of one bake's outputs, lent to the kinds' store() and keep() steps.

    ``report(kind, text)`` reports ("INFO" for a resized image). ``current`` is the index of the job
    being stored and ``notes`` the list its warnings go to (the service sets them; :meth:`warn`).
    Every image a job prepares is snapshot (mc_ao.images.Snapshot) the first time, for :meth:`restore`.
    """

    def __init__(self, settings, folder, files, report):
        self.settings = settings
        self.folder = folder  # the output folder, or None without Save to File
        self.files = files  # the planned files, {image name: [OutputFile]}, or {}
        self.link_relative = settings.output_dir.startswith("//")
        self.report = report
        self.notes = None
        self.snapshots = {}  # job index -> {image name: Snapshot}
        self.current = None
        self.object_name = ""

    def image(self, name, width, height, float_buffer, i=None):
        """The image ``name``, created or reused at this size; prepared (and snapshot) once per job.

        Looked up by name each time and never kept: an undo frees and re-reads image datablocks.
        """
        import bpy

        from .. import images

        i = self.current if i is None else i
        snapshots = self.snapshots.setdefault(i, {})
        image = bpy.data.images.get(name)
        if name not in snapshots:
            image, snapshot = images.prepare_image(name, width, height, float_buffer)
            snapshots[name] = snapshot
            if not snapshot.created and all(snapshot.size) and snapshot.size != (width, height):
                self.report("INFO", f"{self.object_name}: image {name!r} was {snapshot.size[0]}x{snapshot.size[1]}, "
                                    f"resized to {width}x{height}")
        elif image is None or tuple(image.size) != (width, height):
            image, _ = images.prepare_image(name, width, height, float_buffer)
        return image

    def warn(self, text):
        """A warning about the object being stored (without its name): into its outcome's notes."""
        if self.notes is not None:
            self.notes.append(text)
        else:
            self.report("WARNING", f"{self.object_name}: {text}")

    def prepared(self, i):
        return bool(self.snapshots.get(i))

    def restore(self, i, created=True):
        """Put job ``i``'s images back as they were (``created`` False: leave the ones it created,
        which an undo already took away)."""
        for snapshot in self.snapshots.pop(i, {}).values():
            if created or not snapshot.created:
                snapshot.restore()

    def finished(self, i):
        """Job ``i`` is done: its images stay."""
        self.snapshots.pop(i, None)

    def restore_all(self, created=True):
        for i in list(self.snapshots):
            self.restore(i, created)


def keep_image(run, job, name, plane, float_buffer, saved):
    """Make a finished image survive save, reopen and undo: its saved file (Link to File), else its
    pixels packed. ``plane()`` gives its pixels again where loading the file failed."""
    import bpy

    from .. import images, undo_images

    link = saved is not None and run.settings.link_to_file
    if link:
        try:
            images.use_file(bpy.data.images[name], saved, relative=run.link_relative)
            undo_images.record(bpy.data.images[name])  # undo and redo show this bake's pixels or the last's
            return
        except (images.ImageError, RuntimeError) as exc:
            run.warn(f"{exc}; its pixels are packed into the .blend file instead")
    try:
        if link:  # the pixels, after use_file failed
            images.finish_image(name, plane(), float_buffer)
        images.pack(bpy.data.images[name])
        undo_images.record(bpy.data.images[name])
    except images.ImageError as exc:
        run.warn(f"{exc}; save the image (Image > Save As) before closing the .blend file")
