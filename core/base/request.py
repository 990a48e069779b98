"""A bake request: every option of a bake defined once (type, default, limits, meaning), validated once.

:data:`OPTIONS` is the one list of a bake's options. :class:`BakeRequest`, a frozen dataclass with one
field per option, is made from it; making one checks every value and the rules between them, and
refuses bad input with a :class:`~core.base.errors.SettingsError` that names the option and the
problem, before any heavy work. The public calls (:func:`core.bake_ao` and the others) turn their
keywords into a request (:meth:`BakeRequest.from_options`: an unknown keyword is a TypeError that
names the closest option); the pipeline reads nothing else. A worker process gets the request as
plain data (:meth:`BakeRequest.to_dict`, :meth:`BakeRequest.from_dict`): in Blender the parent's core
is ``bl_ext.<repository>.mc_ao.core`` and a worker's is ``core``, so no core object is pickled.

The meshes and arrays of a bake are not options: the target, its occluders, the high-poly meshes, the
cage, the corners to bake and the bent normals' space go to the calls beside the request, and so do
the callbacks (progress, cancel, on_tile, on_rays).

This module imports neither numpy nor embreex (the add-on maps its settings onto :data:`OPTIONS`
when it registers, before the core's dependencies are loaded); numpy's integers and floats are
taken where Python's are (``numbers.Integral``, ``numbers.Real``).
"""

import dataclasses
import difflib
import math
import numbers
from dataclasses import dataclass

from .errors import SettingsError

#: Largest image side the baker accepts (the same as Blender's image size limit).
MAX_RESOLUTION = 65536
#: Most samples per texel. Chunks stay bounded for any count (a texel's samples are traced in
#: pieces), but the sample pool grows with it: 2^20 keeps it to tens of MiB, and a reference bake
#: rarely needs a tenth of it.
MAX_SAMPLES = 1 << 20
#: The largest seed: seeds are hashed as unsigned 64-bit integers.
MAX_SEED = (1 << 64) - 1
#: Most threads a bake (or one worker process) takes.
MAX_THREADS = 1024
#: Most independent randomisations (replicates) a texel's samples may be split into.
MAX_REPLICATES = 16
#: Directions over the hemisphere: cosine-weighted (importance sampling) or uniform.
DISTRIBUTIONS = ("cosine", "uniform")
#: The point sets a texel's samples come from (:mod:`core.montecarlo.sources`, one class each).
SOURCES = ("sobol", "stratified", "independent", "halton")
#: What a bake estimates: ambient occlusion, or the thickness map (:mod:`core.engine.thickness`).
QUANTITIES = ("ao", "thickness")
#: What a bake fills: an image's texels, every UDIM tile the UVs touch, or face corners.
KINDS = ("image", "udim", "corners")
#: UDIM tile numbers (Blender's): 1001 + u + 10 v for u in 0..9, v in 0..99.
FIRST_TILE, LAST_TILE = 1001, 2000


@dataclass(frozen=True)
class Option:
    """One option of a bake.

    name : the keyword of the public calls and the field of :class:`BakeRequest`.
    kind : how its value is checked: 'int', 'float', 'distance' (>= 0, inf allowed), 'bool', 'choice'
        (one of ``choices``), or one of the kinds of a value of its own shape: 'resolution', 'threads',
        'workers', 'tile_size', 'ground', 'extrusion', 'quantities', 'tiles' (see :func:`_check`).
    default : the value when not given.
    group : 'sampling', 'rays', 'target', 'selected_to_active', 'outputs' or 'execution'.
    meaning : what it does (the calls' docs say it at length).
    lo, hi : limits of an 'int' or 'float' (None: none); choices : a 'choice''s values.
    kinds : the bakes that take it (:data:`KINDS`).
    """

    name: str
    kind: str
    default: object
    group: str
    meaning: str
    lo: object = None
    hi: object = None
    choices: tuple = ()
    kinds: tuple = KINDS


IMAGE = ("image", "udim")
OPTIONS = (
    # sampling
    Option("samples", "int", 256, "sampling", "the most samples per texel (every texel takes exactly this many "
           "when adaptive sampling is off)", lo=1, hi=MAX_SAMPLES),
    Option("min_samples", "int", 16, "sampling", "with adaptive sampling, what every texel takes before it may stop",
           lo=1),
    Option("target_error", "float", 0.0, "sampling", "adaptive sampling when > 0: a texel stops once the "
           "half-width of its 95% confidence interval is at most this (AO units); with denoise, of the "
           "denoised map's (image bakes: core.post.denoise.aim); 0 turns it off", lo=0.0),
    Option("distribution", "choice", "cosine", "sampling", "directions: 'cosine' (importance sampling) or "
           "'uniform' (weight 2 cos theta)", choices=DISTRIBUTIONS),
    Option("source", "choice", "sobol", "sampling", "the point set of each texel's samples", choices=SOURCES),
    Option("seed", "int", 0, "sampling", "the same seed gives a bit-identical result for any threads and "
           "processes", lo=0, hi=MAX_SEED),
    Option("replicates", "int", 2, "sampling", "independent randomisations a texel's samples are split into "
           "(with 2 or more, the standard error is the error the estimate really makes)", lo=1,
           hi=MAX_REPLICATES),
    # rays
    Option("max_distance", "float", float("inf"), "rays", "occluders farther than this along a ray do not count "
           "(world units; inf: no limit)"),
    Option("falloff", "float", 0.0, "rays", "0 for plain AO; p > 0 weighs a hit at distance t by "
           "(1 - t / max_distance)^p (needs a finite max_distance)", lo=0.0),
    Option("ignore_backfaces", "bool", False, "rays", "hits on the back of a triangle do not occlude"),
    Option("ground", "ground", None, "rays", "None, 'auto' (the baked surface's lowest point) or a height: an "
           "analytic infinite ground plane z = height that occludes"),
    Option("quantity", "choice", "ao", "rays", "'ao' or 'thickness' (AO with the normal inverted, occluded by "
           "the object alone)", choices=QUANTITIES),
    Option("quantities", "quantities", None, "rays", "several quantities from one bake (distinct names of "
           "'ao', 'thickness'); None: the one ``quantity``"),
    Option("thickness_distance", "distance", 0.0, "rays", "how far a thickness map's rays look into the mesh "
           "(world units); 0: max_distance where it is finite, else a twentieth of the target's size (its "
           "bounding box's diagonal), as the bake's result metadata says"),
    # target
    Option("resolution", "resolution", (1024, 1024), "target", "(width, height) in texels, or one side",
           kinds=IMAGE),
    Option("margin", "int", 16, "target", "texels to extend each UV island by, from the nearest covered texel",
           lo=0, kinds=IMAGE),
    Option("tiles", "tiles", None, "target", "the UDIM tiles to bake (None: every tile the UVs touch)",
           kinds=("udim",)),
    Option("empty_ok", "bool", False, "target", "a bake whose UVs cover no texel returns an all-zero result "
           "instead of raising MeshError", kinds=("image",)),
    Option("merge", "bool", True, "target", "corners with the same vertex and normal share one sample point",
           kinds=("corners",)),
    # selected to active
    Option("extrusion", "extrusion", None, "selected_to_active", "with high-poly meshes: how far the matching "
           "rays start out from the target along its normal (world units); None or 'auto': measured",
           kinds=IMAGE),
    Option("max_ray_distance", "distance", 0.0, "selected_to_active", "with high-poly meshes: the longest matching "
           "ray (world units), 0 for no limit", lo=0.0, kinds=IMAGE),
    # outputs
    Option("bent_normals", "bool", False, "outputs", "also estimate each texel's bent normal from the same rays"),
    Option("denoise", "bool", False, "outputs", "filter the estimate over the surface; the result's error is the "
           "denoised map's (needs replicates >= 2)"),
    Option("fix_seams", "bool", True, "outputs", "after the bake (and the denoiser): make both sides of every "
           "smooth UV seam agree as Blender's Linear interpolation reads them (least squares, each texel held "
           "by its error; texels no seam lookup reads keep their bits, the error covers what changed)",
           kinds=IMAGE),
    # execution
    Option("threads", "threads", None, "execution", "threads of this process, or of each worker process "
           "(None: every core, or one per worker)"),
    Option("workers", "workers", 1, "execution", "1 (this process), N worker processes, 'auto', or a "
           "distributed.Client"),
    Option("tile_size", "tile_size", None, "execution", "the texels a thread takes at a time: a side or "
           "(columns, rows), multiples of 16 (None: chosen from the image, threads and samples)", kinds=IMAGE),
    Option("chunk_rays", "int", 1 << 16, "execution", "rays traced per call into Embree (bounds memory)", lo=1),
    Option("constant_answer", "bool", False, "execution", "benchmarks only: no query reaches Embree (every ray "
           "unoccluded); the result is not AO", kinds=IMAGE),
)
BY_NAME = {o.name: o for o in OPTIONS}


def _int(value, what, lo, hi=None, above=None):
    if isinstance(value, bool) or not isinstance(value, numbers.Integral):
        raise SettingsError(f"{what} must be an integer, got {value!r}")
    if value < lo:
        raise SettingsError(f"{what} must be at least {lo}, got {value}")
    value = int(value)
    if hi is not None and value > hi:
        raise SettingsError(above.format(value) if above else f"{what} must be at most {hi}, got {value}")
    return value


#: How an int option above its limit is refused (the limit said the way a user thinks of it).
_ABOVE = {
    "samples": f"samples must be at most {MAX_SAMPLES} per texel, got {{}}",
    "seed": f"seed must be at most 2**64 - 1 ({MAX_SEED}), got {{}}",
}


def check_resolution(resolution):
    """(width, height) of a resolution given as one side or a pair, checked."""
    if isinstance(resolution, numbers.Integral) and not isinstance(resolution, bool):
        resolution = (resolution, resolution)
    try:
        w, h = resolution
    except (TypeError, ValueError):
        raise SettingsError(f"resolution must be an integer or a (width, height) pair, got {resolution!r}") from None
    w = _int(w, "resolution width", 1)
    h = _int(h, "resolution height", 1)
    if w > MAX_RESOLUTION or h > MAX_RESOLUTION:
        raise SettingsError(f"resolution {w} x {h} exceeds the largest supported side, {MAX_RESOLUTION}")
    return w, h


def _float(value, what):
    if isinstance(value, str) or not isinstance(value, numbers.Real) and not hasattr(value, "__float__"):
        raise SettingsError(f"{what} must be a number, got {value!r}")
    try:
        return float(value)
    except (TypeError, ValueError):
        raise SettingsError(f"{what} must be a number, got {value!r}") from None


def _distance(value, what):
    try:
        value = float(value)
    except (TypeError, ValueError):
        raise SettingsError(f"{what} must be a number, got {value!r}") from None
    if math.isnan(value) or value < 0:
        raise SettingsError(f"{what} must be a distance >= 0, got {value}")
    return value


def check_ground(value):
    """``None``, ``'auto'`` or a finite world height (float); anything else raises SettingsError
    naming the setting."""
    if value is None:
        return None
    if isinstance(value, str):
        if value == "auto":
            return "auto"
        raise SettingsError(f"ground must be None, 'auto' (the baked object's lowest point) or a height, "
                            f"got the string {value!r}")
    if type(value).__name__ in ("bool", "bool_") or not isinstance(value, numbers.Real):
        raise SettingsError(f"ground must be None, 'auto' or a height (a number), got {type(value).__name__} "
                            f"{value!r}")
    h = float(value)
    if not math.isfinite(h):
        raise SettingsError(f"the ground height must be a finite number, got {h}")
    return h


def check_quantity(quantity):
    """'ao' or 'thickness'; anything else raises SettingsError naming the setting."""
    if not isinstance(quantity, str) or quantity not in QUANTITIES:
        raise SettingsError(f"quantity must be one of {', '.join(repr(q) for q in QUANTITIES)}, got {quantity!r}")
    return quantity


def check_quantities(quantities):
    """The quantities as a tuple of distinct names of :data:`QUANTITIES` (one name alone is taken as
    a tuple of it); anything else raises SettingsError naming the setting."""
    if isinstance(quantities, str):
        quantities = (quantities,)
    try:
        given = list(quantities)
    except TypeError:
        raise SettingsError(f"quantities must be a list of {', '.join(repr(q) for q in QUANTITIES)}, "
                            f"got {quantities!r}") from None
    if not given:
        raise SettingsError(f"quantities is empty: name at least one of {', '.join(repr(q) for q in QUANTITIES)}")
    out = tuple(check_quantity(q) for q in given)
    twice = sorted({q for q in out if out.count(q) > 1})
    if twice:
        raise SettingsError(f"quantities names {', '.join(repr(q) for q in twice)} more than once: {list(given)!r}")
    return out


def check_tiles(tiles):
    """The tile numbers, sorted and unique, after checking that each is a UDIM tile (1001 .. 2000)."""
    out = []
    for t in tiles:
        if isinstance(t, bool) or not isinstance(t, numbers.Integral) or not FIRST_TILE <= t <= LAST_TILE:
            raise SettingsError(f"UDIM tile {t!r} does not exist: tiles are numbered {FIRST_TILE} to {LAST_TILE}")
        out.append(int(t))
    return sorted(set(out))


def is_dask_client(workers):
    """Whether ``workers`` is a ``distributed.Client`` (by what it does: submit, scatter, gather)."""
    return hasattr(workers, "submit") and hasattr(workers, "scatter") and hasattr(workers, "gather")


def check_workers(workers):
    """``workers`` as given to :func:`core.bake_ao`: 1, a count, 'auto', or a ``distributed.Client``
    (refused otherwise)."""
    if isinstance(workers, str) and workers == "auto" or is_dask_client(workers):
        return workers
    if isinstance(workers, bool) or not isinstance(workers, numbers.Integral) or workers < 1:
        raise SettingsError(f"workers must be a positive integer or 'auto', got {workers!r}")
    return int(workers)


def _check_tile_size(tile_size):
    if tile_size is None:
        return None
    if isinstance(tile_size, (tuple, list)) and len(tile_size) == 2:
        return tuple(_int(t, "tile_size", 1) for t in tile_size)
    return _int(tile_size, "tile_size", 1)


def _check_bool(value, name):
    if isinstance(value, str):
        raise SettingsError(f"{name} must be True or False, got {value!r}")
    return bool(value)


def _check(option, value):
    """The value of ``option`` checked (and put in its plain form), or SettingsError."""
    kind, name = option.kind, option.name
    if kind == "int":
        return _int(value, name, option.lo, option.hi, _ABOVE.get(name))
    if kind == "float":
        return _float(value, name)  # limits: checked together with the other numbers (_check_numbers)
    if kind == "distance":
        return _distance(value, "the max ray distance (0 = no limit)")
    if kind == "bool":
        return _check_bool(value, name)
    if kind == "choice":
        if not isinstance(value, str) or value not in option.choices:
            if name == "quantity":
                return check_quantity(value)
            what = {"distribution": "distribution", "source": "sample source"}.get(name, name)
            raise SettingsError(f"unknown {what} {value!r}; choose one of {', '.join(option.choices)}")
        return value
    if kind == "resolution":
        return check_resolution(value)
    if kind == "threads":
        return None if value is None else _int(value, "threads", 1, MAX_THREADS)
    if kind == "workers":
        return check_workers(value)
    if kind == "tile_size":
        return _check_tile_size(value)
    if kind == "ground":
        return check_ground(value)
    if kind == "extrusion":
        if value is None or isinstance(value, str) and value == "auto":
            return None
        value = _distance(value, "the extrusion")
        if not math.isfinite(value):
            raise SettingsError(f"the extrusion must be a finite distance, got {value}")
        return value
    if kind == "quantities":
        return None if value is None else check_quantities(value)
    if kind == "tiles":
        return None if value is None else tuple(check_tiles(value))
    raise AssertionError(f"option {name!r} has no check for its kind {kind!r}")


def _check_numbers(v):
    """The float options' limits, in the order and words the bake has always said them."""
    if not (math.isfinite(v["target_error"]) and v["target_error"] >= 0):
        raise SettingsError(f"target_error must be a finite number >= 0 (0 turns adaptive sampling off), "
                            f"got {v['target_error']}")
    if not (v["max_distance"] > 0):  # also refuses NaN
        raise SettingsError(f"max_distance must be positive (inf for unlimited), got {v['max_distance']}")
    if not (math.isfinite(v["falloff"]) and v["falloff"] >= 0):
        raise SettingsError(f"falloff must be a finite number >= 0, got {v['falloff']}")
    if v["falloff"] > 0 and not math.isfinite(v["max_distance"]):
        raise SettingsError("a distance falloff needs a finite max_distance to fall off over")


def base_quantity(quantities):
    """The quantity whose settings are checked and laid out first: 'ao' where it is baked (its
    settings are the larger set), else the first."""
    return "ao" if "ao" in quantities else quantities[0]


def _check_together(v, kind):
    """The rules between options (``v``: the checked values, by name)."""
    _check_numbers(v)
    base = base_quantity(v["quantities"]) if v["quantities"] is not None else v["quantity"]
    if base == "thickness":
        if v["ground"] is not None:
            raise SettingsError(f"ground={v['ground']!r} does not apply to a thickness map, which only the object "
                                "itself occludes; leave ground None for quantity='thickness'")
        if v["ignore_backfaces"]:
            raise SettingsError("ignore_backfaces does not apply to a thickness map: its rays meet the far side "
                                "from behind, so nothing would count; leave it off for quantity='thickness'")
    if v["denoise"] and min(v["replicates"], v["samples"]) < 2:
        unit = "point" if kind == "corners" else "texel"
        raise SettingsError(f"denoise needs replicates >= 2: the filter weighs each {unit} by its standard error, "
                            "which one replicate only bounds")
    if v["bent_normals"] and base != "ao":
        raise SettingsError(f"bent normals come with quantity='ao' only, not {base!r}: bake them in an AO bake")


def _field(option):
    default = option.default
    if isinstance(default, (list, dict, set)):
        return option.name, object, dataclasses.field(default_factory=lambda d=default: type(d)(d))
    return option.name, object, dataclasses.field(default=default)


class _Request:
    """The methods of :class:`BakeRequest` (its fields are :data:`OPTIONS`)."""

    def __post_init__(self):
        if self.kind not in KINDS:
            raise SettingsError(f"kind must be one of {', '.join(KINDS)}, got {self.kind!r}")
        v = {o.name: _check(o, getattr(self, o.name)) for o in OPTIONS}
        _check_together(v, self.kind)
        for name, value in v.items():
            object.__setattr__(self, name, value)

    @classmethod
    def from_options(cls, call, kind, options):
        """The request of the public call named ``call`` (for its errors) for a bake of ``kind``,
        from its keyword ``options``: a keyword that names no option, or an option the bake of
        ``kind`` does not take, is a TypeError naming the closest option (as Python names an
        unexpected keyword)."""
        for name in options:
            option = BY_NAME.get(name)
            if option is None or name == "kind" or kind not in option.kinds:
                raise TypeError(unexpected(call, name, kind))
        return cls(kind=kind, **options)

    def to_dict(self):
        """The request as plain data (numbers, strings, tuples, None): what a worker process rebuilds
        it from (:meth:`from_dict`). A ``distributed.Client`` given as ``workers`` is left out."""
        out = {"kind": self.kind}
        for o in OPTIONS:
            value = getattr(self, o.name)
            if o.kind == "workers" and is_dask_client(value):
                continue
            out[o.name] = value
        return out

    @classmethod
    def from_dict(cls, data):
        """The request of :meth:`to_dict`'s plain data, checked again."""
        unknown = sorted(set(data) - set(BY_NAME) - {"kind"})
        if unknown:
            raise TypeError(unexpected("BakeRequest.from_dict", unknown[0], data.get("kind", "image")))
        return cls(**data)

    def replace(self, **changes):
        """A copy with ``changes``, checked."""
        return dataclasses.replace(self, **changes)

    @property
    def base_quantity(self):
        """The quantity laid out first (:func:`base_quantity`): the one quantity, or 'ao' among several."""
        return self.quantity if self.quantities is None else base_quantity(self.quantities)

    @property
    def all_quantities(self):
        """The quantities this bake makes, in order."""
        return (self.quantity,) if self.quantities is None else self.quantities


def unexpected(call, name, kind):
    """The TypeError message for keyword ``name`` of ``call`` (a bake of ``kind``): the closest option
    it may have meant."""
    option = BY_NAME.get(name)
    if option is not None and name != "kind":
        takes = " and ".join({"image": "images", "udim": "UDIM tiles", "corners": "mesh corners"}[k]
                             for k in option.kinds)
        return (f"{call}() got an unexpected keyword argument {name!r}: {name} applies to bakes of {takes}, "
                f"not of {dict(image='images', udim='UDIM tiles', corners='mesh corners')[kind]}")
    names = [o.name for o in OPTIONS if kind in o.kinds]
    close = difflib.get_close_matches(name, names, n=1, cutoff=0.0) if isinstance(name, str) else []
    hint = f"; did you mean {close[0]!r}?" if close else ""
    return f"{call}() got an unexpected keyword argument {name!r}{hint}"


BakeRequest = dataclasses.make_dataclass(
    "BakeRequest", [("kind", object, dataclasses.field(default="image"))] + [_field(o) for o in OPTIONS],
    bases=(_Request,), frozen=True)
BakeRequest.__module__ = __name__
BakeRequest.__doc__ = (
    """The options of one bake, checked (see the module docstring). Fields: ``kind`` (:data:`KINDS`)
    and one per option of :data:`OPTIONS`, each its checked value: ``resolution`` a (width, height)
    pair, ``quantities`` a tuple or None, ``tiles`` a sorted tuple or None, ``extrusion`` a distance
    or None (measured), ``tile_size`` None, a side or a pair.""")


__all__ = ["Option", "OPTIONS", "BY_NAME", "BakeRequest", "MAX_RESOLUTION", "MAX_SAMPLES", "MAX_SEED", "MAX_THREADS",
           "MAX_REPLICATES", "DISTRIBUTIONS", "SOURCES", "QUANTITIES", "KINDS", "FIRST_TILE", "LAST_TILE",
           "check_resolution", "check_ground", "check_quantity", "check_quantities", "check_tiles", "check_workers",
           "is_dask_client", "base_quantity", "unexpected"]
