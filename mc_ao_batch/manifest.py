"""The batch manifest (TOML): reading it, checking every setting, and planning one task per .blend file.

A manifest::

    [defaults]              # any setting of scripts/bake_ao.py, as its option name with '_' for '-'
    resolution = 1024
    samples = 128
    format = ["exr"]

    [[bake]]
    blend = "props/chair.blend"   # relative to the manifest's folder
    objects = ["Chair"]           # optional: default, as bake_ao.py (every mesh with a UV map ...)
    samples = 256                 # overrides [defaults] for this file
    rebake_older = true           # optional (also in [defaults]): bake it again when its files were
                                  # made by an older output version (default: report them and keep them)

The keys, and the shape of each value, are mc_ao.schema's (its settings and the script's own options);
each entry becomes its task's command line, which is read by the bake script's own parser and checked
as the script checks it (mc_ao.settings.from_options: every value, every rule of mc_ao.rules) before
anything runs, so an unknown name or a bad value stops the whole batch with exit status 2 and a message
naming the entry; what only the bake can tell (an object missing from its file, a broken file) fails
that task alone.

Each task writes into ``OUTPUT/<folder>/``, ``<folder>`` being the .blend file's stem made safe by
:func:`core.files.filenames.safe_file_stem`. Files whose stems clash (``a/chair.blend`` and
``b/chair.blend``, or ``Chair`` and ``chair`` on a case-insensitive disk) all get a hash of their path
relative to the manifest appended, so no task writes into another's folder and the folder a file gets
does not depend on the order of the entries.
"""

import argparse
import hashlib
import json
import os
import tomllib
from dataclasses import asdict, dataclass, field
from pathlib import Path

from core._version import OUTPUT_VERSION
from core.files.filenames import safe_file_stem
from mc_ao import schema
from mc_ao import settings as mc_ao_settings
from mc_ao.filecheck import file_key
from mc_ao.terminal import escape


#: The batch summary's file name in the output folder; no task folder may take it.
BATCH_SUMMARY = "mc_ao_batch.json"
# bake_ao.py options the batch sets itself, per task; a manifest may not.
_RUNNER_OPTIONS = {o.key for o in schema.OPTIONS if o.batch is False} | {"blend"}
# bake_ao.py options that do not change a single output byte (the bake is bit-identical for any
# thread count): left out of a task's fingerprint.
_NO_EFFECT = {"threads", "processes", "quiet", "output", "summary_json", "blend"}
# Settings added after fingerprints were first recorded: left out while at their default, so that a
# library baked before them is still found done.
_ADDED_AT_DEFAULT = {"denoise": False, "occluder_collections": [], "exclude_collections": [], "only_local": False,
                     "ground": False, "ground_height": None, "quantity": ["ao"], "channel": "none", "into": "",
                     "images": "own", "atlas": None, "id_map": False, "match_collections": False,
                     "fix_seams": True}
# The settings made of a core option by themselves (mc_ao.schema.FROM_CORE: a core option that the add-on
# does not map), at their defaults as the script's parser gives them: left out of fingerprints at their
# default too, so that a new option of the core finds a library baked before it done.
_FROM_CORE_AT_DEFAULT = {s.option_key: (bool(s.default) if s.kind == "bool" else schema.cli_value(s.default) if s.kind == "enum"
                                        else s.default) for s in schema.FROM_CORE}
_ENTRY_KEYS = {"blend"}
# Keys of [defaults] and [[bake]] entries that are the batch's own, not bake_ao.py settings: never on
# the bake's command line, never in a fingerprint.
_BATCH_KEYS = {"rebake_older"}
#: The mc_ao version whose fingerprints had no output version in them: output version 1's.
_LEGACY_MC_AO = "0.1.0"
# bake_ao.py options a batch task cannot take, and why (mc_ao.schema.OPTIONS: one --save path for
# every task would have each task replace the last one's file).
_NOT_IN_BATCH = {o.key: o.batch for o in schema.OPTIONS if isinstance(o.batch, str)}


class ManifestError(Exception):
    """A manifest that cannot be run: exit status 2, nothing baked."""


@dataclass
class Task:
    """One .blend file to bake: everything a process anywhere needs to run it (JSON-able)."""

    index: int               # 1-based position in the manifest's [[bake]] list
    name: str                # the task's folder under the output folder
    blend: str               # absolute path of the .blend file
    blend_given: str         # the path as the manifest gives it
    output: str              # absolute path of OUTPUT/<name>
    args: list               # bake_ao.py settings (no --output, --summary-json, --quiet, --threads)
    threads: int = 0         # --threads for the bake; 0 = all cores of the machine that runs it
    processes: int = 0       # --processes for the bake; 0 = the bake's own choice (the entry's, or from the cores)
    fingerprint: str = ""    # hash of everything that decides the output's bytes
    objects: list = field(default_factory=list)  # the objects the entry names ([] = bake_ao's default)
    # [output version, fingerprint] of the same task under every older output version, newest first:
    # where a library made by an older version keeps its summary.
    older: list = field(default_factory=list)
    rebake_older: bool = False  # bake again what an older output version made (else keep it)

    @property
    def summary(self):
        """Where bake_ao.py writes this task's --summary-json: its name carries the fingerprint."""
        return self.summary_of(self.fingerprint)

    def summary_of(self, fingerprint):
        """The summary's path of this task under ``fingerprint`` (its own, or an older output version's)."""
        return os.path.join(self.output, f"mc_ao-{fingerprint[:16]}.json")

    @property
    def log(self):
        return os.path.join(self.output, f"mc_ao-{self.fingerprint[:16]}.log")

    def to_dict(self):
        return asdict(self)

    @classmethod
    def from_dict(cls, data):
        return cls(**data)


def bake_script_module():
    """mc_ao.cli, the logic of scripts/bake_ao.py (it imports no bpy), for its argument parser and checks."""
    from mc_ao import cli

    return cli


def bake_parser():
    """bake_ao.py's parser for a plain Python (the .blend file first), raising ManifestError on a bad argument."""
    parser = bake_script_module().make_parser(with_blend=True)

    class Parser(type(parser)):
        def error(self, message):
            raise ManifestError(message)

    parser.__class__ = Parser
    parser.exit_on_error = False  # a value argparse cannot convert raises instead of exiting
    return parser


def check_settings(namespace):
    """The bake's own check of every setting's value and every rule between them (mc_ao.settings.
    from_options: the schema's limits, mc_ao.rules' rules, formats and bit depths), as the script checks
    its command line; fills in the formats' default as the script does."""
    bake_script_module().default_formats(namespace)
    _, problems = mc_ao_settings.from_options(namespace)
    if problems:
        raise ManifestError("; ".join(escape(p) for p in problems))


def settings_spec():
    """bake_ao.py's settings a manifest may set, from mc_ao.schema: ``key -> (option, shape)``, the
    shape one of "value", "value?", "list", "pair", "flag", "switch" (mc_ao.schema.manifest_keys)."""
    return schema.manifest_keys()


def _value_args(where, key, value, spec):
    """The command-line words for one manifest setting (``spec``: its option and shape)."""
    flag, shape = spec
    nargs = {"list": "+", "pair": 2, "value?": "?"}.get(shape)
    if shape in ("flag", "switch"):
        if not isinstance(value, bool):
            raise ManifestError(f"{where}: {key} must be true or false, not {value!r}")
        # a switch is on unless said otherwise: false is its --no- option
        return [flag] if value else ([] if shape == "flag" else ["--no-" + flag[2:]])
    if isinstance(value, dict):
        raise ManifestError(f"{where}: {key} must be a value or a list, not a table")
    if nargs == "+":
        values = value if isinstance(value, list) else [value]
        if not values:
            raise ManifestError(f"{where}: {key} must not be empty")
    elif isinstance(nargs, int):  # match_suffix = ["_high", "_low"]
        if not isinstance(value, list) or len(value) != nargs:
            raise ManifestError(f"{where}: {key} takes a list of {nargs} values, not {value!r}")
        values = value
    else:
        if isinstance(value, list):
            if key == "resolution" and len(value) == 2 and all(isinstance(v, int) for v in value):
                value = f"{value[0]}x{value[1]}"
            else:
                raise ManifestError(f"{where}: {key} takes one value, not a list")
        if isinstance(value, bool):
            raise ManifestError(f"{where}: {key} takes a value, not {str(value).lower()}")
        values = [value]
    for v in values:
        if isinstance(v, (dict, list)) or isinstance(v, bool):
            raise ManifestError(f"{where}: {key}: {v!r} is not a plain value")
    words = [_word(v) for v in values]
    if len(words) == 1 and nargs is None:
        # "--uv-map=-x": a value that starts with '-' stays this option's value
        return [f"{flag}={words[0]}"] if words[0].startswith("-") else [flag, words[0]]
    for word in words:
        if word.startswith("-"):
            # a list's items follow the option word by word: one that starts with '-' would be read
            # as an option of its own ("--overwrite-input")
            raise ManifestError(f"{where}: {key}: {word!r} starts with '-': a manifest's values are values, "
                                "never an option; rename it")
    return [flag] + words


def _word(value):
    if isinstance(value, float):
        return repr(value)  # 'inf', '0.01': what float() reads back exactly
    return str(value)


def _check_keys(where, table, spec, allowed_extra):
    for key in table:
        if key in _NOT_IN_BATCH:
            raise ManifestError(f"{where}: {key!r} cannot be set in a batch: {_NOT_IN_BATCH[key]}")
        if key in spec or key in allowed_extra:
            continue
        hint = ""
        if key.replace("-", "_") in spec:
            hint = f" (write it {key.replace('-', '_')!r})"
        elif key in _RUNNER_OPTIONS:
            hint = " (the batch sets it for each task)"
        raise ManifestError(
            f"{where}: unknown setting {key!r}{hint}; settings: {', '.join(sorted(spec))}"
        )


def _check_batch_keys(where, table):
    value = table.get("rebake_older", False)
    if not isinstance(value, bool):
        raise ManifestError(f"{where}: rebake_older must be true or false, not {value!r}")


def load(path):
    """Read a manifest file: ``(defaults, entries)`` as plain dicts, checked for shape only."""
    path = Path(path)
    try:
        with open(path, "rb") as f:
            data = tomllib.load(f)
    except FileNotFoundError:
        raise ManifestError(f"no such manifest: {path}") from None
    except tomllib.TOMLDecodeError as exc:
        raise ManifestError(f"{path}: not valid TOML: {exc}") from None
    except OSError as exc:
        raise ManifestError(f"cannot read the manifest {path}: {exc.strerror or exc}") from None
    unknown = set(data) - {"defaults", "bake"}
    if unknown:
        raise ManifestError(
            f"{path}: unknown table {', '.join(sorted(unknown))!s}; a manifest has [defaults] and [[bake]] entries"
        )
    defaults = data.get("defaults", {})
    entries = data.get("bake", [])
    if not isinstance(defaults, dict):
        raise ManifestError(f"{path}: defaults must be a table ([defaults])")
    if not isinstance(entries, list) or not all(isinstance(e, dict) for e in entries):
        raise ManifestError(f"{path}: bake must be an array of tables ([[bake]])")
    if not entries:
        raise ManifestError(f"{path}: no [[bake]] entries")
    return defaults, entries


def _blend_identity(path):
    """Size and modification time of the .blend file (None when it is missing: the task will say so)."""
    try:
        st = os.stat(path)
    except OSError:
        return None
    return {"size": st.st_size, "mtime_ns": st.st_mtime_ns}


def _into_file(base, into):
    """The Into file of an entry as a full path, when ``into`` names a file relative to the manifest's folder
    ``base`` (as ``blend`` does) or an absolute one; None when it names no file there (a Blender image of the
    .blend file, which the bake looks up by name)."""
    if not isinstance(into, str) or not into:
        return None
    path = os.path.normpath(base / os.path.expanduser(into))
    return path if os.path.isfile(path) else None


def _fingerprint(blend_given, identity, namespace, output_version=OUTPUT_VERSION):
    """The hash of everything that decides a task's output: the .blend file, the settings and the output
    version (``output_version`` 1: the record of the versions before output versions, which named the
    mc_ao version instead, so that their libraries are found)."""
    at_default = {**_ADDED_AT_DEFAULT, **_FROM_CORE_AT_DEFAULT}
    settings = {k: v for k, v in vars(namespace).items()
                if k not in _NO_EFFECT and not (k in at_default and v == at_default[k])}
    made_by = {"mc_ao": _LEGACY_MC_AO} if output_version == 1 else {"output_version": int(output_version)}
    record = dict(made_by, blend=blend_given, file=identity, settings=settings)
    text = json.dumps(record, sort_keys=True, default=lambda v: list(v) if isinstance(v, tuple) else str(v))
    return hashlib.sha256(text.encode()).hexdigest()


def _folder_names(entries):
    """``blend_given -> folder name``: safe stems, and a path hash on every stem that clashes."""
    stems = {e: safe_file_stem(Path(e).stem or "blend") for e in entries}
    groups = {}
    for e, s in stems.items():
        groups.setdefault(s.casefold(), []).append(e)
    names = {}
    for key, members in groups.items():
        clash = len(members) > 1 or key == BATCH_SUMMARY.casefold()
        for e in members:
            if clash:
                tag = hashlib.sha256(Path(e).as_posix().encode()).hexdigest()[:8]
                names[e] = safe_file_stem(f"{stems[e]}-{tag}")
            else:
                names[e] = stems[e]
    return names


def plan(manifest_path, output, *, threads=0, processes=0):
    """The tasks of a manifest, every setting checked: a list of :class:`Task`.

    ``threads``: --threads for tasks whose entry does not set it (0 = all cores); ``processes``:
    --processes for tasks whose entry sets neither (0: the bake picks them).
    Raises :class:`ManifestError` for anything that stops the whole batch.
    """
    manifest_path = Path(manifest_path)
    defaults, entries = load(manifest_path)
    spec = settings_spec()
    base = manifest_path.resolve().parent
    output = Path(output).resolve()

    where = f"{manifest_path}: [defaults]"
    _check_keys(where, defaults, spec, _BATCH_KEYS)
    _check_batch_keys(where, defaults)
    if "objects" in defaults:
        raise ManifestError(f"{where}: objects belong to a [[bake]] entry, not to [defaults]")

    given, seen = [], {}
    for n, entry in enumerate(entries, 1):
        where = f"{manifest_path}: [[bake]] entry {n}"
        blend = entry.get("blend")
        if not isinstance(blend, str) or not blend.strip():
            raise ManifestError(f"{where}: blend = \"path/to/file.blend\" is required")
        where += f" ({blend})"
        _check_keys(where, entry, spec, _ENTRY_KEYS | _BATCH_KEYS)
        _check_batch_keys(where, entry)
        resolved = file_key(os.path.normpath(base / os.path.expanduser(blend)))  # by the file it reaches
        if resolved in seen:
            raise ManifestError(
                f"{where}: the same file as entry {seen[resolved]}; one entry per .blend file "
                "(list all its objects in one entry)"
            )
        seen[resolved] = n
        given.append(blend)
    names = _folder_names(given)

    parser = bake_parser()
    tasks = []
    for n, entry in enumerate(entries, 1):
        blend = entry["blend"]
        where = f"{manifest_path}: [[bake]] entry {n} ({blend})"
        settings = dict(defaults)
        settings.update({k: v for k, v in entry.items() if k not in _ENTRY_KEYS})
        rebake_older = settings.pop("rebake_older", False)
        into_given = settings.get("into")
        into_file = _into_file(base, into_given)
        if into_file is not None:
            settings["into"] = into_file  # the bake runs elsewhere: the file beside the manifest, by its full path
        args = []
        for key in sorted(settings):
            args += _value_args(where, key, settings[key], spec[key])
        blend_path = os.path.normpath(base / os.path.expanduser(blend))
        try:
            namespace = parser.parse_args([blend_path] + args)
            check_settings(namespace)
        except (ManifestError, argparse.ArgumentError) as exc:
            raise ManifestError(f"{where}: {exc}") from None
        task_threads = threads
        task_processes = 0 if "processes" in settings or "threads" in settings else processes
        if "threads" in settings:
            # the runner passes --threads itself, for every task
            task_threads = namespace.threads
            i = args.index("--threads")
            del args[i:i + 2]
        objects = list(namespace.objects or [])
        task = Task(
            index=n, name=names[blend], blend=blend_path, blend_given=blend,
            output=str(output / names[blend]), args=args, threads=task_threads, processes=task_processes,
            objects=objects,
        )
        identity = _blend_identity(blend_path)
        if into_file is not None:
            # the Into file is an input too: a changed file bakes again; the path as given, so that a
            # library moved with its manifest still counts as done
            namespace = argparse.Namespace(**dict(vars(namespace), into=into_given,
                                                  into_file=_blend_identity(into_file)))
        task.fingerprint = _fingerprint(Path(blend).as_posix(), identity, namespace)
        task.older = [[v, _fingerprint(Path(blend).as_posix(), identity, namespace, v)]
                      for v in range(OUTPUT_VERSION - 1, 0, -1)]
        task.rebake_older = rebake_older
        tasks.append(task)
    return tasks
