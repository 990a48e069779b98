"""The outputs of a bake, one kind per file, each with the same steps (mc_ao.outputs.base):

| kind | file | what it writes |
|---|---|---|
| ``image`` | image.py | the AO in the object's image (plain or UDIM tiles) and its files |
| ``error_map`` | error_map.py | the standard error in "<image>_stderr" and ``<stem>_stderr.exr`` |
| ``bent_normals`` | bent_normals.py | the bent normals in "<object>_BentNormal" and its files |
| ``channel`` | channel.py | the map in one channel of an existing image (Channel, Into) and a copy of its file |
| ``id_map`` | id_map.py | a shared image's ID map: "<image>_ID", each object's texels in its own colour |
| ``color_attribute`` | color_attribute.py | the AO in a colour attribute and a PLY file |

``maps.py`` is what every image kind shares (a kind of map chooses its plane of the core's result,
``source(result)``), ``udim_tiles.py`` the tiled side of every map, ``store.py`` the Blender images
the kinds fill and put back, ``base.py`` the steps and the all-or-none save of an object's files.

A new kind: a subclass in a new file, and its class in :data:`KINDS` (in the order its files and
summary lines come). No bpy at import. Nothing here imports mc_ao.service, cli or operators.
"""

from .base import FileWrite, OutputKind, SaveError, save_files  # noqa: F401
from .bent_normals import BentNormalsOutput
from .channel import ChannelOutput
from .color_attribute import ColorAttributeOutput
from .error_map import ErrorMapOutput
from .id_map import IdMapOutput
from .image import ImageOutput

#: Every kind of output, in the order their files are planned and written.
KINDS = (ImageOutput, ErrorMapOutput, BentNormalsOutput, IdMapOutput, ChannelOutput, ColorAttributeOutput)


def kinds_for(settings):
    """The outputs of a bake with ``settings``: each kind that applies, bound to them."""
    return [kind(settings) for kind in KINDS if kind.applies(settings)]


def quantities(kinds):
    """The core results the kinds need, in the order the service bakes them: None (each job's own
    bake) first, then each other quantity a kind names."""
    return [None] + [q for q in dict.fromkeys(q for k in kinds for q in (k.quantity, *k.extra_quantities))
                     if q is not None]


def check(kinds, job):
    """Raise images.ImageError (without the object's name) when Blender's data cannot take the job's outputs."""
    for kind in kinds:
        kind.check(job)


def output_files(kinds, folder, jobs, formats):
    """{name: [mc_ao.filewriter.OutputFile]} of every kind's files over ``jobs``: distinct, safe file
    names over all of them (mc_ao.filewriter.output_files). ``formats``: [(file_format, bits)]."""
    from dataclasses import replace

    from .. import filewriter

    fixed = [k.file_formats for k in kinds if getattr(k, "file_formats", None)]
    formats = fixed[0] if fixed else formats
    stderr = any(getattr(k, "stderr_file", False) for k in kinds)
    names, owners = [], {}
    for kind in kinds:
        for job in jobs:
            for name in kind.file_names(job):
                other = owners.setdefault(name, kind)
                if other is not kind:  # two kinds' files under one name: one would replace the other
                    from .. import corelink

                    raise corelink.load().SettingsError(
                        f"{job.object_name}: its {other.what} and its {kind.what} would both be saved as "
                        f"{name!r}; one would replace the other: {kind.clash_hint()}")
                names.append(name)
    plan = filewriter.output_files(folder, names, formats, stderr=stderr)
    first = kinds[0] if kinds else None
    for name, kind in owners.items():
        if kind is not first:  # the standard error goes with the first kind's (the AO's) files only
            plan[name] = [replace(f, stderr_path=None) for f in plan[name]]
    return plan


def plan_files(kinds, folder, jobs, formats):
    """output_files(), checked before anything is baked: a planned file that would replace a file of
    another kind raises core.FileWriteError naming every such path."""
    from .. import corelink

    files = output_files(kinds, folder, jobs, formats)
    problems = [p for job in jobs for kind in kinds for p in kind.check_files(job, files)]
    if problems:
        raise corelink.load("base.errors").FileWriteError("; ".join(dict.fromkeys(problems)) + "; nothing was baked")
    return files


def planned_paths(files):
    """Every path of a bake's planned files: images, standard errors, PLY."""
    import os

    return [os.fspath(p) for entry in files.values() for f in entry for p in (f.path, f.stderr_path) if p]
