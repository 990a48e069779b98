"""The outputs of a finished bake, by kind, for the operator and the script: which images a job
needs (:func:`check_images`), where its files go (:func:`output_files`: AO, standard error, bent
normals, a colour-attribute bake's PLY) and writing them (:func:`write_files`: per UDIM tile too), the
summary line of a bake that is not a plain image (:func:`summary`), and for the operator the end of
such a job in Blender (:func:`finish_job`: colour attribute or tiled images, saved, linked) and the
bent-normal image beside a plain one (:func:`finish_bent`, :func:`save_bent`).

Importing it needs no bpy; the functions that touch Blender data import it. It imports nothing above
it (mc_ao.operators, mc_ao.cli call it).
"""

import os

from . import corelink
from .baking import id_name_max_bytes, input_notes, throughput
from .extract import ExtractError


def custom(settings):
    """Whether a job's end differs from a plain image bake's (handled here, not by the operator)."""
    return settings.vertex_colors or settings.use_udim


def check_images(job, settings):
    """Raise images.ImageError (without the object's name) when the job's images cannot take the bake."""
    from . import images, udim

    if settings.vertex_colors:
        return
    names = [job.image_name] + ([bent_name(job, settings)] if settings.bent_normals else [])
    if settings.use_udim and settings.error_map:  # the tiled "<image>_stderr" (a plain one: the operator's)
        names.append(stderr_name(job, settings))
    w, h = settings.size
    for name in names:
        if settings.use_udim:
            udim.check_image(name, w, h)
        else:
            images.check_target(name)


def bent_name(job, settings):
    return settings.bent_image_name_for(job.object_name, id_name_max_bytes())


def stderr_name(job, settings):
    return settings.quantity_image_name_for(job.object_name, job.quantity, id_name_max_bytes(), "_stderr")


# -- files --------------------------------------------------------------------------------------

def output_files(settings, folder, jobs_, formats, stderr=False):
    """{image name: [OutputFile]} for the AO images (and bent-normal images) of ``jobs_``: distinct,
    safe names over all of them (mc_ao.filewriter.output_files). A colour-attribute bake gets one PLY
    file per object, named like its image would be."""
    from dataclasses import replace

    from . import filewriter

    names = [j.image_name for j in jobs_]
    if settings.vertex_colors:
        return filewriter.output_files(folder, names, [("PLY", None)])
    bents = [bent_name(j, settings) for j in jobs_] if settings.bent_normals else []
    plan = filewriter.output_files(folder, names + bents, formats, stderr=stderr)
    for name in bents:
        plan[name] = [replace(f, stderr_path=None) for f in plan[name]]
    return plan


def plan_files(settings, folder, jobs_, formats, stderr=False):
    """output_files(), checked before anything is baked: a planned file that would replace an existing
    file of another kind raises core.FileWriteError naming every such path (the operator and the
    script both plan their files here)."""
    from . import filewriter

    files = output_files(settings, folder, jobs_, formats, stderr=stderr)
    problems = filewriter.planned_kind_problems(files)
    if problems:
        raise corelink.load("errors").FileWriteError("; ".join(problems) + "; nothing was baked")
    return files


def write_files(job, result, files, metadata, settings):
    """Write a finished job's files, every kind; ``(written, failures)`` as mc_ao.filewriter.write_outputs.

    ``files``: output_files()'s dict. The AO image (and its standard error) to its files; UDIM: each
    tile to ``<name>.<tile>.<ext>``; bent normals to the "<object>_BentNormal" files; a
    colour-attribute bake to its PLY file.
    """
    from . import bent, filewriter, udim, vertex_colors

    written, failures = [], []
    meta = dict(metadata)
    if settings.vertex_colors:
        plyio = corelink.load("plyio")
        data = job.target.extra
        positions, sizes, verts, ao = vertex_colors.ply_data(result, data, settings.attribute_domain)
        meta = dict(result.metadata, **meta, content="ao")
        for f in files[job.image_name]:
            problem = filewriter.kind_problem(f.path)
            if problem is not None:
                failures.append((f.path, corelink.load("errors").FileWriteError(problem)))
                continue
            try:
                filewriter.make_output_folder(os.path.dirname(f.path))
                plyio.write_ply(f.path, positions, sizes, verts, ao, meta)
                written.append(f.path)
            except (corelink.load().McAoError, OSError) as exc:
                failures.append((f.path, exc))
        return written, failures
    results = result.tiles if settings.use_udim else {None: result}
    for tile, res in results.items():
        own = files[job.image_name] if tile is None else udim.tile_files(files[job.image_name], tile)
        tile_meta = meta if tile is None else dict(meta, udim_tile=tile)
        w, f = filewriter.write_outputs(res, own, tile_meta)
        written += w
        failures += f
        if settings.bent_normals:
            name = bent_name(job, settings)
            own = files[name] if tile is None else udim.tile_files(files[name], tile)
            w, f = bent.write_files(bent.encoded(res, settings), own,
                                    dict(res.metadata, **tile_meta, content="bent_normal",
                                         bent_space=settings.bent_space.lower()))
            written += w
            failures += f
    return written, failures


def summary(job, result, settings):
    """The summary line of a job that is not a plain image (None for a plain one)."""
    per, rate = throughput(result)
    if settings.vertex_colors:
        domain = "per vertex" if settings.attribute_domain == "POINT" else "per face corner"
        return (f"{job.object_name}: {len(result.ao)} face corners into color attribute "
                f"{settings.attribute_name!r} ({domain}) in {result.seconds:.2f} s, {per:.0f} samples per "
                f"corner, {rate:.2f} M rays/s")
    if settings.use_udim:
        tiles = sorted(result.tiles)
        w, h = settings.size
        listed = ", ".join(map(str, tiles))
        return (f"{job.object_name}: {len(tiles)} UDIM tile{'s' if len(tiles) != 1 else ''} ({listed}) of {w}x{h} "
                f"into {job.image_name!r} in {result.seconds:.2f} s, {per:.0f} samples per texel, "
                f"{rate:.2f} M rays/s")
    return None


# -- the operator's end of a job (main thread) ----------------------------------------------------

def finish_job(session, context, i, result):
    """End job ``i`` of the operator's BakeSession for a colour-attribute or UDIM bake: store the
    result (attribute, tiled images), save its files, report its notes and summary."""
    import bpy

    from . import images, udim, vertex_colors

    job = session.run.jobs[i]
    settings = session.settings
    session.pending.discard(i)
    session.buffers.pop(i, None)
    try:
        if settings.vertex_colors:
            obj = bpy.data.objects.get(job.object_name)
            if obj is None:
                raise ExtractError("the object is gone")
            vertex_colors.write_attribute(obj, settings, result, job.target.extra)
        else:
            images_ = {job.image_name: ({t: images.rgba(r.ao) for t, r in result.tiles.items()},
                                        settings.float_buffer)}
            if settings.bent_normals:
                from . import bent

                images_[bent_name(job, settings)] = ({t: bent.rgba(bent.encoded(r, settings))
                                                      for t, r in result.tiles.items()}, settings.float_buffer)
            if settings.error_map:  # the tiled "<image>_stderr", float, the same tiles as the AO
                images_[stderr_name(job, settings)] = ({t: images.rgba(r.stderr) for t, r in result.tiles.items()},
                                                       True)
            for name, (tiles, float_buffer) in images_.items():
                udim.fill(name, tiles, float_buffer)
    except (ExtractError, images.ImageError, RuntimeError) as exc:
        session.errors += 1
        session.report({"ERROR"}, f"{job.object_name}: {exc}")
        return
    session.finished.append(i)
    session.results.append(result)
    if session.output_dir is not None:
        saved = _save(session, job, result)
        if saved is None:
            session.unsummarised_errors += 1
        elif settings.use_udim and settings.link_to_file:
            _link_udim(session, job, result)
    for note in input_notes(result):
        session._warn(f"{job.object_name}: {note}")
    session._summarise(summary(job, result, settings))


def _save(session, job, result):
    """Write the job's files; report them; the written paths, or None after a failure (reported)."""
    import bpy

    from . import filewriter

    settings = session.settings
    metadata = filewriter.file_metadata(settings, job, bpy.data.filepath)
    try:
        files = output_files(settings, session.output_dir, session.run.jobs,
                             [(settings.file_format, settings.file_bits)], stderr=settings.error_map)
        written, failures = write_files(job, result, files, metadata, settings)
    except corelink.load().McAoError as exc:
        written, failures = [], [(session.output_dir, exc)]
    for path, exc in failures:
        session.file_errors += 1
        why = str(exc) if path in str(exc) else f"{path}: {exc}"
        where = (f"color attribute {settings.attribute_name!r}" if settings.vertex_colors
                 else f"image {job.image_name!r}")
        session.report({"ERROR"}, f"{job.object_name}: the bake is in {where}, but its file was not saved "
                                  f"(any file already there is unchanged): {why}")
    if written:
        session.report({"INFO"}, f"{job.object_name}: saved {', '.join(written)} ({filewriter.writer_name()})")
    return written if written and not failures else None


def _link_udim(session, job, result):
    """Point the tiled images at their saved tiles (Link Image to File) where the bake wrote every
    tile of the image; an image with other tiles stays packed (said so)."""
    import bpy

    from . import images, udim

    settings = session.settings
    files = output_files(settings, session.output_dir, session.run.jobs, [(settings.file_format, settings.file_bits)],
                         stderr=settings.error_map)
    paths = {job.image_name: files[job.image_name][0].path}
    if settings.bent_normals:
        paths[bent_name(job, settings)] = files[bent_name(job, settings)][0].path
    if settings.error_map:  # "<image>_stderr" onto <stem>_stderr.<UDIM>.exr
        paths[stderr_name(job, settings)] = files[job.image_name][0].stderr_path
    for name, path in paths.items():
        image = bpy.data.images.get(name)
        if image is None:
            continue
        if {t.number for t in image.tiles} - set(result.tiles):
            session._warn(f"{job.object_name}: image {name!r} has tiles the bake did not write; its pixels are "
                          "packed into the .blend file instead of loading from the saved files")
            continue
        try:
            udim.link_files(name, path, settings.output_dir.startswith("//"))
        except (images.ImageError, RuntimeError) as exc:
            session._warn(f"{job.object_name}: {exc}; its pixels are packed into the .blend file instead")


def finish_bent(session, i, result):
    """After job ``i``'s AO image is finished (plain images): its "<object>_BentNormal" image,
    created or reused like the AO image, packed or linked to its saved file. False after an error
    (reported; the bent image is put back as it was)."""
    import bpy

    from . import bent, images

    settings = session.settings
    if not settings.bent_normals or result.bent is None:
        return True
    job = session.run.jobs[i]
    name = bent_name(job, settings)
    h, w = result.ao.shape
    try:
        _, snapshot = images.prepare_image(name, w, h, settings.float_buffer)
    except images.ImageError as exc:
        session.report({"ERROR"}, f"{job.object_name}: {exc}")
        return False
    try:
        images.finish_image(name, bent.encoded(result, settings), settings.float_buffer)
        images.pack(bpy.data.images[name])
    except (images.ImageError, RuntimeError) as exc:
        snapshot.restore()
        session.report({"ERROR"}, f"{job.object_name}: {exc}")
        return False
    return True


def save_bent(session, job, result, saved_ao):
    """With Save to File (plain images): write the bent-normal files; link the image to its file."""
    import bpy

    from . import bent, filewriter, images

    settings = session.settings
    if not settings.bent_normals or result.bent is None or session.output_dir is None:
        return
    name = bent_name(job, settings)
    files = output_files(settings, session.output_dir, session.run.jobs,
                         [(settings.file_format, settings.file_bits)])[name]
    metadata = dict(result.metadata, **filewriter.file_metadata(settings, job, bpy.data.filepath),
                    content="bent_normal", bent_space=settings.bent_space.lower())
    written, failures = bent.write_files(bent.encoded(result, settings), files, metadata)
    for path, exc in failures:
        session.file_errors += 1
        session.unsummarised_errors += 1
        session.report({"ERROR"}, f"{job.object_name}: the bent normals are in image {name!r}, but their file was "
                                  f"not saved (any file already there is unchanged): {exc}")
    if written:
        session.report({"INFO"}, f"{job.object_name}: saved {', '.join(written)} ({filewriter.writer_name()})")
        if settings.link_to_file and not failures:
            try:
                images.use_file(bpy.data.images[name], written[0], relative=settings.output_dir.startswith("//"))
            except (images.ImageError, RuntimeError) as exc:
                session._warn(f"{job.object_name}: {exc}; its pixels are packed into the .blend file instead")
                images.finish_image(name, bent.encoded(result, settings), settings.float_buffer)
                images.pack(bpy.data.images[name])
