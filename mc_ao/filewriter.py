"""Where a bake's files go and how they are written, the same for the operator, the script and the
batch: needs no bpy to import.

- :func:`output_files`: where each job's files go. File names come from the jobs' image names (which
  come from object names, chosen by whoever made the .blend file) through
  :func:`core.files.filenames.unique_file_stems` (one safe, distinct stem per image, also where names
  differ only in case) and :func:`core.files.filenames.path_inside` (the final path lies in the output
  folder). Nothing else turns a name into a path.
- :func:`writer_name`: the one image writer: OpenImageIO through core.files.imageio where its Python
  module exists (Blender's official builds), else Blender's own image writer (Debian's Blender has
  no OpenImageIO module). Both write a temporary file, check it and only then replace the target
  (:mod:`core.files.atomicfile`); an object's files are written together, all or none
  (mc_ao.outputs.save_files); the only folder ever created is the chosen output folder itself
  (:func:`make_output_folder`); a file of another kind at a path is never replaced (:func:`kind_problem`).
- :func:`settings_record` and :func:`file_metadata`: the bake's settings as written into every
  file's metadata (and into the script's ``--summary-json``).
"""

import importlib.util
import os
from dataclasses import dataclass

from . import corelink
from .schema import FROM_CORE
from .settings import FILE_FORMATS

# The image file formats of the Format setting (PLY is a colour-attribute bake's own, chosen by its target).
IMAGE_FORMATS = tuple(f for f in FILE_FORMATS if f != "PLY")


def settings_record(settings):
    """The bake's settings as written into every file's metadata (core's names for them).

    The same dict goes into ``--summary-json``, so a later run can check a file against the bake
    that was asked for. Unlimited max_distance is ``inf`` (``Infinity`` in the JSON, as Python's
    json writes and reads it). A Selected to Active bake adds its settings (Cycles' names).
    """
    kw = settings.bake_kwargs()
    w, h = kw["resolution"]
    record = {
        "samples": int(kw["samples"]),
        "min_samples": int(kw["min_samples"]),
        "target_error": float(kw["target_error"]),
        "sample_source": kw["source"],
        "distribution": kw["distribution"],
        "seed": int(kw["seed"]),
        "max_distance": float(kw["max_distance"]),
        "margin": int(kw["margin"]),
        "ignore_backfaces": bool(kw["ignore_backfaces"]),
        "resolution": f"{w}x{h}",
        "occluders": settings.occluders.lower(),
        "uv_map": settings.uv_map,
        # UDIM tiles, colour attributes, bent normals: recorded only when on (a plain bake's record
        # stays as it was, so that its files still count as done).
        **({"udim": True} if settings.use_udim else {}),
        **({"target": "vertex_colors", "attribute": settings.attribute_name,
            "domain": settings.attribute_domain.lower()} if settings.target == "VERTEX_COLORS" else {}),
        **({"bent_normals": settings.bent_space.lower()} if settings.bent_normals else {}),
        **({"denoise": True} if settings.denoise else {}),
        # Fix Seams is on for every image bake unless turned off: recorded only then
        **({"fix_seams": False} if not settings.fix_seams and settings.target != "VERTEX_COLORS" else {}),
        # which objects occlude, the ground and the quantities: recorded only where not the default
        **({"occluder_collections": ", ".join(settings.occluder_collections)}
           if settings.occluder_collections else {}),
        **({"exclude_collections": ", ".join(settings.exclude_collections)} if settings.exclude_collections else {}),
        **({"only_local": True} if settings.only_local else {}),
        **({"ground": settings.ground.lower()} if settings.ground != "OFF" else {}),
        **({"ground_height": float(settings.ground_height)} if settings.ground == "HEIGHT" else {}),
        **({"quantity": " ".join(settings.quantities)} if settings.quantities != ("ao",) else {}),
        "replicates": int(kw["replicates"]),
        # the core's options that are settings by themselves (mc_ao.schema.FROM_CORE): where not the default
        **{s.core: kw[s.core] for s in FROM_CORE if getattr(settings, s.name) != s.default},
    }
    if getattr(settings, "use_selected_to_active", False):
        record.update({"selected_to_active": True, "cage_extrusion": float(settings.cage_extrusion),
                       "max_ray_distance": float(settings.max_ray_distance),
                       "use_cage": bool(settings.use_cage),
                       "cage_object": settings.cage_object if settings.use_cage else ""})
    return record


def file_metadata(settings, job, blend_path):
    """What every file of ``job`` carries, whoever writes it (the operator, the script, the batch): the
    settings record, the object, the .blend file's name, and a Selected to Active bake's high-poly
    objects and cage. One dict for all three, so that they write the same bytes."""
    metadata = dict(settings_record(settings), object=job.object_name,
                    blend=os.path.basename(os.fspath(blend_path or "")))
    if getattr(job, "quantity", "ao") != "ao":
        metadata["map"] = job.quantity  # what this file holds, where the bake made more than AO
    if getattr(job, "selected_to_active", False):
        metadata.update(highpoly=", ".join(h.name for h in job.highpoly),
                        cage=job.cage.name if job.cage is not None else "")
    return metadata


# -- files -----------------------------------------------------------------------------------------

@dataclass(frozen=True)
class OutputFile:
    """One file of a job: where, in which format and depth, and where its standard error goes (or None)."""

    path: str
    file_format: str  # "PNG", "OPEN_EXR" or "TIFF" (mc_ao.settings.FILE_FORMATS)
    bits: object  # 8, 16, "half" or "float", as core.files.imageio takes them
    stderr_path: str = None


#: Suffix of the standard-error file of an image (always a float EXR).
STDERR_SUFFIX = "_stderr.exr"


def output_files(folder, image_names, formats, stderr=False):
    """Every file each image of a bake goes to: ``{image_name: [OutputFile, ...]}``.

    Parameters
    ----------
    folder : str
        The output folder (absolute or relative to the working directory).
    image_names : list of str
        The images of all the bake's jobs: file names are made distinct over all of them at once.
    formats : list of (file_format, bits)
        One file per entry, e.g. ``[("PNG", 8), ("OPEN_EXR", "half")]``.
    stderr : bool
        Also write each image's standard error, with its first format, to ``<stem>_stderr.exr``.

    Raises
    ------
    core.SettingsError
        Two files would be one (also on a filesystem that ignores case), or a path would leave
        ``folder`` (core.files.filenames.UnsafePathError, a subclass).
    """
    filenames = corelink.load("files.filenames")
    core = corelink.load()
    stems = filenames.unique_file_stems(image_names)
    taken = {}  # path, case-folded -> the image whose file it is

    def place(name, file_name):
        path = filenames.path_inside(folder, file_name)
        other = taken.get(path.casefold())
        if other is not None:
            raise core.SettingsError(
                f"the images {other!r} and {name!r} would both be saved as {file_name!r}; rename one"
                if other != name else f"image {name!r} would be saved twice as {file_name!r}"
            )
        taken[path.casefold()] = name
        return path

    plan = {}
    for name in dict.fromkeys(image_names):
        stem = stems[name]
        files = []
        for k, (file_format, bits) in enumerate(formats):
            path = place(name, stem + FILE_FORMATS[file_format][0])
            stderr_path = place(name, stem + STDERR_SUFFIX) if stderr and k == 0 else None
            files.append(OutputFile(path, file_format, bits, stderr_path))
        plan[name] = files
    return plan


def oiio_available():
    """Whether core.files.imageio can write files here (it needs the OpenImageIO Python module)."""
    return importlib.util.find_spec("OpenImageIO") is not None


def writer_name():
    """The image writer used here: "OpenImageIO" or "Blender"."""
    return "OpenImageIO" if oiio_available() else "Blender"


def make_output_folder(folder):
    """Create the output folder (only it, and its missing parents) if it does not exist yet."""
    if os.path.isdir(folder):
        return
    core = corelink.load()
    try:
        os.makedirs(folder, exist_ok=True)
    except OSError as exc:
        raise core.ImageWriteError(f"could not create the output folder {folder!r}: {exc.strerror or exc}") from exc


def kind_problem(*paths):
    """The first of ``paths`` (None ones skipped) that holds a file of another kind than a bake writes
    there, as a message; None when every one may be written (mc_ao.filecheck.replace_problem)."""
    from . import filecheck

    for path in paths:
        problem = path and filecheck.replace_problem(path)
        if problem:
            return problem
    return None
