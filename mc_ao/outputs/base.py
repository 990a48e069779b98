"""What every kind of output does, in the same steps, and the all-or-none save of an object's files.

An output kind (:class:`OutputKind`) is bound to one bake's settings and goes through these steps
for each object (a job) of the bake:

1. ``check(job)`` and ``check_files(job, files)``, before anything is baked: the Blender data it
   will write can take the bake (an image of another kind, a tile of another size, a colour
   attribute of another type raise), and none of its planned files would replace a file of another
   kind (a list of problems);
2. ``quantity`` (and ``extra_quantities``): the core results it needs: None is the job's own bake
   (each job bakes one quantity, mc_ao.baking.Job.quantity); a named one is baked once more per
   job for it (mc_ao.bakerun.BakeRun);
3. ``store(run, job, results)``: the finished bake into Blender's data (images, tiles, a colour
   attribute), for the operator (and the script's ``--save``);
4. ``writes(job, results, files, metadata)``: its files as :class:`FileWrite` s, which
   :func:`save_files` writes together, all or none; then ``keep(run, job, results, saved)``: a
   stored image loads from its saved file (Link to File) or is packed into the .blend file;
5. ``summarise(job, results)``: its part of the object's summary line, or None.

``results`` maps each quantity to the core's result for it (None: the job's own). ``run`` is what the service lends a
kind to touch Blender data with: ``run.image(name, w, h, float_buffer)`` (an image created or
reused, put back as it was when the object does not finish), ``run.warn(text)``, ``run.folder``
(the output folder, or None), ``run.link_relative`` (store linked paths relative to the .blend).

No bpy at import; the steps that touch Blender import it.
"""

import os
from dataclasses import dataclass
from typing import Callable

from .. import corelink, filewriter


class OutputKind:
    """One kind of output of a bake, bound to the bake's settings (:mod:`mc_ao.settings`).

    Subclasses set ``name`` (the registry's key, what a summary calls it) and override the steps
    they take part in; the defaults do nothing.
    """

    name = "output"
    #: What its files hold, in a message ("image", "copy of the Into image").
    what = "output"
    #: The core result this kind is made from: None for the job's own bake (its ``quantity``, "ao"
    #: or "thickness"), else a core quantity baked once more for it.
    quantity = None
    #: Other core results it reads too (a channel-packed image: "thickness" beside the AO).
    extra_quantities = ()

    def __init__(self, settings):
        self.settings = settings

    @classmethod
    def applies(cls, settings):
        """Whether a bake with ``settings`` has this output."""
        return False

    def clash_hint(self):
        """What to change when its file would have the name of another kind's file."""
        return "rename one of the images"

    # 1. before any work
    def check(self, job):
        """Raise images.ImageError (without the object's name) when Blender's data cannot take it."""

    def check_files(self, job, files):
        """Why its planned files cannot be written (paths of a file of another kind): a list of texts."""
        return [p for f in self.planned(job, files) for p in [filewriter.kind_problem(f)] if p]

    def planned(self, job, files):
        """The paths of its files for ``job`` (``files``: :func:`plan_files`' dict)."""
        return []

    # 3. into Blender
    def store(self, run, job, results):
        """Put the finished bake into Blender's data (raise images.ImageError, ExtractError, RuntimeError)."""

    # 4. files
    def writes(self, job, results, files, metadata):
        """Its files of the finished ``job`` as FileWrite s (written together by :func:`save_files`)."""
        return []

    def keep(self, run, job, results, saved):
        """After the files: make what store() put into Blender survive save and undo (``saved``:
        the paths written, [] when none)."""

    # 5. the report
    def summarise(self, job, results):
        """Its summary line for ``job``, or None (the plain image's is the operator's and the script's own)."""
        return None


@dataclass
class FileWrite:
    """One file of an object: where, and how: ``write(target)`` writes the complete file at ``target``
    with a checking writer (core.files.imageio, core.files.plyio, Blender's through mc_ao.images), raising
    core.McAoError, OSError or RuntimeError when it cannot."""

    path: str
    write: Callable
    what: str = "file"
    planned: str = None  # the planned path it comes from (a UDIM tile's file: the image's path)
    tile: int = None  # its UDIM tile, or None


class SaveError(Exception):
    """None of an object's files were written: ``failures`` [(path, exception)], ``path`` the first."""

    def __init__(self, failures):
        self.failures = failures
        self.path = failures[0][0]
        super().__init__("; ".join(_why(path, exc) for path, exc in failures))


def _why(path, exc):
    text = str(exc)
    return text if os.fspath(path) in text else f"{os.fspath(path)}: {text}"


def save_files(writes):
    """Write an object's files all together or none of them; the paths written.

    Every file is written to a temporary file beside its target and checked first (a file of
    another kind at a target, an unwritable folder, a full disk, a writer that fails: nothing is
    replaced); only then are the temporary files moved over their targets, together
    (core.files.atomicfile.commit_together: a failed move puts back the files already moved). Raises
    :class:`SaveError` naming the files that failed; every old file is then as it was.
    """
    writes = list(writes)
    if not writes:
        return []
    atomicfile = corelink.load("files.atomicfile")
    core = corelink.load()
    errors = corelink.load("base.errors")
    problems = [(w.path, errors.FileWriteError(p)) for w in writes for p in [filewriter.kind_problem(w.path)] if p]
    if problems:
        raise SaveError(problems)
    staged = []
    try:
        for w in writes:
            try:
                filewriter.make_output_folder(os.path.dirname(os.path.abspath(w.path)))
                pending = atomicfile.PendingFile(w.path, error=core.ImageWriteError)
            except (core.McAoError, OSError) as exc:
                raise SaveError([(w.path, exc)]) from None
            staged.append(pending)
            try:
                w.write(os.fspath(pending.temp))
                pending.finish()
            except (core.McAoError, OSError, RuntimeError, ValueError) as exc:
                text = str(exc).replace(os.fspath(pending.temp), os.fspath(w.path))
                raise SaveError([(w.path, core.ImageWriteError(text))]) from None
        try:
            atomicfile.commit_together(staged, error=core.ImageWriteError)
        except (core.McAoError, OSError) as exc:
            raise SaveError([(getattr(exc, "filename", None) or writes[0].path, exc)]) from None
    except BaseException:
        for pending in staged:
            pending.discard()
        raise
    return [w.path for w in writes]

