"""The script's command line: its options (one per mc_ao.schema setting that has one, and the
script's own, mc_ao.schema.OPTIONS: what to bake, where files go), the arguments under Blender or a
plain Python, the settings they give (every value and rule checked: mc_ao.settings.from_options), and
UsageError, a refusal before anything is baked (exit status 2). No bpy."""

import argparse
import re
import sys
from pathlib import Path

from .. import schema, settings
from ..terminal import escape

class UsageError(Exception):
    """Bad arguments or input: exit status 2. ``usage``: the usage text to show after the message.

    ``message``: one problem (text), or a list of them, one line each; names in them are escaped
    (mc_ao.terminal.escape), so a name's newline cannot start a line of its own.
    """

    def __init__(self, message, usage=""):
        problems = message if isinstance(message, list) else [message]
        super().__init__("\n".join(escape(str(p)) for p in problems))
        self.usage = usage


class Parser(argparse.ArgumentParser):
    """argparse, but a bad argument raises UsageError (exit 2 with the summary written) instead of exiting."""

    def error(self, message):
        raise UsageError(message, self.format_usage())


def run_by_blender():
    """True when the Blender executable runs this script: it has imported bpy before running it."""
    return "bpy" in sys.modules


def script_argv(argv=None):
    if argv is not None:
        return list(argv)
    if run_by_blender():
        return sys.argv[sys.argv.index("--") + 1:] if "--" in sys.argv else []
    return sys.argv[1:]


def parse_resolution(text):
    try:
        parts = [int(p) for p in text.lower().split("x")]
    except ValueError:
        parts = []
    if len(parts) not in (1, 2) or min(parts) < 1:
        raise argparse.ArgumentTypeError(f"{text!r} is not a size: use N or WxH, e.g. 1024 or 2048x1024")
    return parts[0], parts[-1]


def script_help(setting):
    """The option's help in the script's words: ``setting.cli_help``, else its tooltip with every other
    setting's panel name (a capitalised label inside a sentence: "stop at Min Samples") as that
    setting's option ("stop at --min-samples")."""
    if setting.cli_help:
        return setting.cli_help
    text = setting.help
    others = sorted((s for s in schema.SETTINGS if s is not setting and s.option is not None),
                    key=lambda s: -len(s.label))  # "Min Samples" before "Samples"
    for other in others:
        # not at the start of the text or of a sentence, where a capital is only a capital
        text = re.sub(rf"(?<![.] )(?<!^)(?<![\w-]){re.escape(other.label)}\b", other.option, text)
    return text


def _add_setting(parser, setting):
    """The option of one schema setting (mc_ao.schema): its type, choices, default and help."""
    option, dest = setting.option, setting.option_key
    default = setting.default
    help_text = script_help(setting).replace("%", "%%")  # argparse formats help with %
    if setting.kind == "bool" and setting.default is True:  # on unless --no-<option>
        parser.add_argument(option, dest=dest, action=argparse.BooleanOptionalAction, default=True,
                            help=f"{help_text} (default: on)")
        return
    if setting.kind == "bool" or setting.flag is not None:
        parser.add_argument(option, dest=dest, action="store_true", help=help_text)
        return
    kwargs = {"dest": dest, "help": f"{help_text} (default: {default!r})"}
    if setting.sets:  # not given: None, so that giving it can set another setting
        kwargs["default"] = None
    if setting.kind in ("enum", "flags"):
        # any case: --channel R
        kwargs.update(choices=[schema.cli_value(i) for i in setting.identifiers], type=str.lower)
        if setting.kind == "enum":
            kwargs["default"] = schema.cli_value(default)
            kwargs["help"] = f"{help_text} (default: {schema.cli_value(default)})"
        else:
            kwargs.update(nargs="+", default=[schema.cli_value(d) for d in default])
            kwargs["help"] = f"{help_text} (default: {' '.join(schema.cli_value(d) for d in default)})"
    elif setting.kind == "collections":
        kwargs.update(nargs="+", default=[], metavar="COLLECTION", help=f"{help_text} (default: none)")
    elif setting.kind == "int":
        kwargs.update(type=int, default=default, metavar="N")
    elif setting.kind in ("float", "distance"):
        kwargs.setdefault("default", default)
        kwargs.update(type=float, metavar="D" if setting.kind == "distance" else "X")
    else:
        kwargs.setdefault("default", default)
        kwargs["metavar"] = "NAME"
    parser.add_argument(option, **kwargs)


def _add_option(parser, option):
    """The argument of one of the script's own options (mc_ao.schema.OPTIONS)."""
    names = [option.option] + ([option.short] if option.short else [])
    if option.shape == "flag":
        parser.add_argument(*names, action="store_true", help=option.help)
        return
    kwargs = {"help": option.help}
    if option.kind == "path":
        kwargs["type"] = Path
    elif option.kind == "size":
        kwargs["type"] = parse_resolution
    if option.default is not None:
        kwargs["default"] = Path(option.default) if option.kind == "path" else option.default
    if option.choices:
        kwargs["choices"] = list(option.choices)
    if option.metavar is not None:
        kwargs["metavar"] = option.metavar
    kwargs["nargs"] = {"list": "+", "pair": 2, "value?": "?"}.get(option.shape)
    if option.shape == "value?":
        kwargs["const"] = ""
    parser.add_argument(*names, **kwargs)


def make_parser(with_blend):
    """The script's options: every mc_ao.schema setting that has an option (its manifest key is the
    option's name with '_' for '-'), and the script's own (mc_ao.schema.OPTIONS)."""
    parser = Parser(
        prog="bake_ao.py",
        description="Bake ambient occlusion of objects in a .blend file into image files.",
        epilog="Under Blender: blender -b -q scene.blend --python scripts/bake_ao.py -- [options]. "
               "Exit status: 0 all baked and written, 1 a bake or file failed, 2 bad arguments or "
               "input (nothing baked), 130 Ctrl-C.",
    )
    if with_blend:
        parser.add_argument("blend", help=".blend file to open")
    for option in schema.OPTIONS:
        if option.section == "files":
            _add_option(parser, option)
    for setting in schema.SETTINGS:
        if setting.option_key is not None and "selected_to_active" not in setting.targets:
            _add_setting(parser, setting)
    s2a = parser.add_argument_group(
        "selected to active", "bake the AO of high-poly objects into a low-poly's UVs (Cycles' Selected to Active)")
    for setting in schema.SETTINGS:
        if setting.option_key is not None and "selected_to_active" in setting.targets:
            _add_setting(s2a, setting)
    for option in schema.OPTIONS:
        if option.section == "selected_to_active":
            _add_option(s2a, option)
    for option in schema.OPTIONS:
        if option.section == "run":
            _add_option(parser, option)
    return parser


def default_formats(args):
    """--format's default: png for images, ply for --target vertex-colors."""
    if getattr(args, "format", None) is None:
        args.format = ["ply"] if getattr(args, "target", "") == "vertex-colors" else ["png"]
    return args.format


def settings_from(args):
    """The BakeSettings of the arguments, after checking every value and rule (UsageError lists what
    is wrong); fills in --format's default."""
    default_formats(args)
    baked, problems = settings.from_options(args)
    if problems:
        raise UsageError(problems)
    return baked


def early_summary_args(argv, in_blender):
    """(summary path, .blend path) from the raw arguments, so that the summary is written even
    when the arguments are refused."""
    pre = Parser(add_help=False)
    pre.add_argument("--summary-json", type=Path)
    if not in_blender:
        pre.add_argument("blend", nargs="?")
    try:
        known, _ = pre.parse_known_args(argv)
    except UsageError:  # a --summary-json without its path: the full parse says so
        return None, None
    if in_blender:
        import bpy

        return known.summary_json, bpy.data.filepath or None
    return known.summary_json, known.blend
