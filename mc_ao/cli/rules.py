"""The script's settings from its options, every value and every rule between them checked before
anything is baked (UsageError lists each problem)."""

from .. import corelink, schema
from ..settings import BakeSettings
from .options import BITS, UsageError, default_formats


def settings_from(args):
    """The BakeSettings of the arguments, after checking every value (UsageError lists what is wrong)."""
    imageio = corelink.load("files.imageio")
    width, height = args.resolution
    values, problems = schema.from_options(args)
    values.update(
        resolution=width, height=height, float_buffer=args.attribute_type == "float",
        use_selected_to_active=bool(args.selected_to_active or args.match_suffix),
        use_cage=args.cage is not None, cage_object=args.cage or "",
    )
    settings = BakeSettings(**values)
    problems += selected_to_active_problems(args)
    for field, message in schema.problems(settings):
        if field in ("resolution", "height"):  # both from --resolution, each at least 1 already
            message = f"--resolution must be at most {corelink.load('engine.settings').MAX_RESOLUTION} a side, not {width}x{height}"
            if message not in problems:
                problems.append(message)
            continue
        problems.append(f"{schema.BY_NAME[field].option or field} {message}")
    problems += target_problems(args, settings)
    if args.bits is not None:
        bits = BITS[args.bits]
        for fmt in args.format:
            if fmt == "ply":
                continue
            allowed = imageio.FORMATS["." + fmt][0]
            if bits not in allowed:
                problems.append(
                    f"--bits {args.bits} cannot be written as {fmt}: {fmt} files take --bits "
                    + " or ".join(str(b) for b in allowed)
                )
    if any(sep in args.image_name for sep in "/\\") or args.image_name in (".", ".."):
        problems.append(f"--image-name {args.image_name!r} is a path: give a name; files go into --output")
    if problems:
        raise UsageError(problems)
    return settings


def target_problems(args, settings):
    """What is wrong with the issue-14 options together (--target, --format, --save, ...)."""
    problems = []
    formats = default_formats(args)
    vertex = settings.target == "VERTEX_COLORS"
    if vertex:
        wrong = [f for f in formats if f != "ply"]
        if wrong:
            problems.append(f"--format {' '.join(wrong)}: --target vertex-colors writes .ply files (--format ply)")
        for flag, on in (("--udim", settings.use_udim), ("--bent-normals", settings.bent_normals)):
            if on:
                problems.append(f"{flag} bakes images; --target vertex-colors bakes a color attribute")
    elif "ply" in formats:
        problems.append("--format ply is for --target vertex-colors; images are written as png, exr or tif")
    save = getattr(args, "save", None)
    if save is not None:
        if not vertex:
            problems.append("--save writes color attributes into a .blend file: it needs --target vertex-colors")
        elif save.suffix.lower() != ".blend":
            problems.append(f"--save {str(save)!r} must name a .blend file")
    return problems


def selected_to_active_problems(args):
    """What is wrong with the Selected to Active options together (their values: schema.problems)."""
    problems = []
    on = args.selected_to_active or args.match_suffix
    if not on:
        for option, given in (("--active", args.active is not None), ("--cage", args.cage is not None),
                              ("--extrusion", args.extrusion != 0.0),
                              ("--max-ray-distance", args.max_ray_distance != 0.0)):
            if given:
                problems.append(f"{option} is a setting of --selected-to-active (or --match-suffix), which is off")
        return problems
    for option, given in (("--target vertex-colors", getattr(args, "target", "") == "vertex-colors"),
                          ("--udim", getattr(args, "udim", False)),
                          ("--bent-normals", getattr(args, "bent_normals", False))):
        if given:
            problems.append(f"{option}: --selected-to-active bakes AO into one image texture of the low-poly")
    if args.match_suffix:
        high, low = args.match_suffix
        if not high or not low or high == low:
            problems.append(f"--match-suffix needs two different, non-empty suffixes, not {high!r} and {low!r}")
        if args.active is not None:
            problems.append("--active names one low-poly; with --match-suffix, --objects names the low-poly objects")
        if args.cage:
            problems.append("--cage NAME names one cage for one low-poly; bake a pair with a cage object with "
                            "--active (--cage alone extrudes each low-poly along its vertex normals)")
    elif args.cage and (args.cage == args.active or args.cage in (args.objects or [])):
        problems.append(f"--cage {args.cage!r} is also the low-poly or one of the high-poly objects")
    if args.active is not None and args.active in (args.objects or []):
        problems.append(f"--active {args.active!r} is also among --objects (the high-poly objects)")
    return problems
