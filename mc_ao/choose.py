"""Which objects a bake takes and their jobs: one function for the operator and the script.

What the user asked for is a :class:`Pick`: the selection and the active object (the operator's
context, the file's for the script), and what the script's options name (``--objects``,
``--active``, ``--match-suffix``, ``--cage NAME``). :func:`choose` turns it into a :class:`Choice`:
the objects, the selected objects it leaves out and notes, or a :class:`ChoiceError` naming the
objects and the problem, before any geometry is read; ``Choice.jobs`` then reads their geometry
into the jobs (mc_ao.baking.plan, mc_ao.selected_to_active.plan).

The rules, the same from either side:

- Named objects that cannot bake are an error; selected ones are skipped (the caller words a note
  for each: ``Choice.skipped``).
- Nothing bakeable selected: the operator refuses (its button is greyed out with the same reason);
  the script (``Pick.script``) bakes every mesh of the view layer that can be baked.
- Selected to Active: the active object (or ``--active``) is the low-poly, the other selected objects
  with a surface (or ``--objects``) the high-poly, the cage aside; ``--match-suffix HIGH LOW`` pairs
  <base>HIGH with <base>LOW, one job per low-poly (a <base>LOW without its <base>HIGH is skipped
  with a note, or is an error when named).
- Occluders "Selected": the operator's selection; the script's baked objects.

Reads Blender data (bpy objects passed in); imports no bpy itself.
"""

from dataclasses import dataclass, field

from . import atlas, baking, selected_to_active
from .extract import GEOMETRY_TYPES, ExtractError


class ChoiceError(ExtractError):
    """The objects asked for cannot bake: the message names them and says why."""


@dataclass
class Pick:
    """What the user asked to bake.

    selected, active : the selected objects and the active one.
    names : objects named (the script's ``--objects``): the targets, or with Selected to Active the
        high-poly objects (with ``match_suffix`` the low-poly ones); empty: the selection.
    active_name : the low-poly named (``--active``); None: the active object.
    match_suffix : ``(HIGH, LOW)``: Selected to Active for every pair <base>HIGH, <base>LOW.
    match_collections : Selected to Active for every low-poly ``names`` names, from the other objects of
        its own collection.
    script : the script's pick: with nothing bakeable selected and nothing named it bakes every mesh
        of the view layer (the operator refuses), the objects it bakes are the "Selected" occluders
        (the operator's: its selection), a cage object must be in the view layer, and its errors say
        which option names an object.
    """

    selected: list
    active: object = None
    names: tuple = ()
    active_name: str = None
    match_suffix: tuple = None
    match_collections: bool = False
    script: bool = False


@dataclass
class Choice:
    """The objects of a bake, chosen (no geometry read yet): ``targets``, each with its high-poly
    objects for Selected to Active (``sources``: target name -> the objects it is baked from, with
    itself and its cage); ``skipped``: selected objects left out (a note each, worded by the caller);
    ``notes``: what else the choice tells the user (which objects it fell back to)."""

    settings: object
    view_layer: object
    targets: list
    occluding: list = field(default_factory=list)  # the occluders "Selected"
    sources: dict = field(default_factory=dict)
    skipped: list = field(default_factory=list)
    notes: list = field(default_factory=list)

    def jobs(self, depsgraph):
        """The Jobs of the chosen objects, their geometry evaluated by ``depsgraph`` (modifiers
        applied): mc_ao.baking.plan's, or mc_ao.selected_to_active.plan's for each low-poly. Raises
        ExtractError naming the object (no faces, no such UV map, two objects into one image, ...)."""
        settings = self.settings
        if settings.images == "OWN" and atlas.shared(settings):  # a named image: one object into it
            max_bytes = baking.id_name_max_bytes()
            baking.check_image_names([(obj.name, settings.image_name_for(obj.name, max_bytes))
                                      for obj in self.targets])
        if not settings.use_selected_to_active:
            if atlas.shared(settings):
                return atlas.plan(depsgraph, self.targets, settings, selected=self.occluding,
                                  view_layer=self.view_layer)
            return baking.plan(depsgraph, self.targets, settings, selected=self.occluding,
                               view_layer=self.view_layer)
        jobs = [selected_to_active.plan(depsgraph, low, self.sources[low.name], settings,
                                        view_layer=self.view_layer) for low in self.targets]
        if atlas.shared(settings):  # the low-poly objects into one image, each from its high-poly
            return atlas.from_selected_to_active(jobs, settings, {low.name: low for low in self.targets})
        baking.check_image_names([(job.object_name, job.image_name) for job in jobs])
        return jobs


def choose(settings, pick, view_layer):
    """The Choice of ``pick`` with ``settings`` (a BakeSettings) in ``view_layer``; ChoiceError naming
    the objects when they cannot bake. Reads no geometry (Choice.jobs does)."""
    if settings.use_selected_to_active:
        return _selected_to_active(settings, pick, view_layer)
    needs_uvs = baking.needs_uvs(settings)
    choice = Choice(settings, view_layer, [])
    if pick.names:
        objects = _named(view_layer, pick.names, "object", "meshes")
        for obj in objects:
            if not baking.can_be_target(obj, needs_uvs):
                raise ChoiceError(f"{obj.name} {baking.skip_reason(obj, needs_uvs)}")
    else:
        objects = baking.targets_of(pick.selected, needs_uvs)
        choice.skipped = [obj for obj in pick.selected if obj not in objects]
        if not objects and pick.script:
            objects = baking.targets_of(view_layer.objects, needs_uvs)
            what = "mesh with a UV map" if needs_uvs else "mesh"
            if not objects:
                raise ChoiceError(f"the file has no {what} to bake")
            choice.skipped = []
            choice.notes.append(f"{f'no {what} is selected' if pick.selected else 'nothing is selected'}; "
                                f"baking every {what}: {', '.join(o.name for o in objects)}")
        elif not objects:
            raise ChoiceError(baking.why_not_bakeable(pick.selected, needs_uvs) or "Nothing to bake")
    choice.targets = objects
    choice.occluding = objects if pick.script else list(pick.selected)
    return choice


def _named(view_layer, names, what, listing="objects"):
    """The view layer's objects of these names, each once (ChoiceError naming the missing ones and
    listing the view layer's ``listing``: "objects" or "meshes")."""
    layer = view_layer.objects
    names = list(dict.fromkeys(names))
    missing = [n for n in names if n not in layer]
    if missing:
        present = sorted(o.name for o in layer if listing == "objects" or o.type == "MESH")
        raise ChoiceError(f"no {what} {', '.join(map(repr, missing))} in the view layer; its {listing}: "
                          f"{', '.join(present) or 'none'}")
    return [layer[n] for n in names]


def _selected_to_active(settings, pick, view_layer):
    """The Choice of a Selected to Active bake: each low-poly with its high-poly objects."""
    if pick.script and settings.use_cage and settings.cage_object:
        _named(view_layer, [settings.cage_object], "cage object")
    cage = selected_to_active.cage_of(settings)
    choice = Choice(settings, view_layer, [])
    if pick.match_suffix:
        pairs = _suffix_pairs(pick, view_layer, choice.notes)
    elif pick.match_collections:
        pairs = _collection_pairs(pick, view_layer, cage)
    else:
        low = _named(view_layer, [pick.active_name], "object")[0] if pick.active_name is not None else pick.active
        if pick.names:
            highs = _named(view_layer, pick.names, "object")
            for obj in highs:
                if obj.type not in GEOMETRY_TYPES:
                    raise ChoiceError(f"{obj.name} is {baking.kind_of(obj)}, not an object with a surface to bake "
                                      "from")
        else:
            if low is None and pick.script:
                raise ChoiceError("--selected-to-active needs --active NAME: the file has no active object")
            highs = [o for o in pick.selected if o is not low and o is not cage]
            if low is not None and pick.script and not highs:
                raise ChoiceError(f"no high-poly objects to bake onto {low.name}: name them with --objects, or "
                                  "select them in the file")
            choice.skipped = [o for o in highs if o.type not in GEOMETRY_TYPES]
            highs = [o for o in highs if o.type in GEOMETRY_TYPES]
            if highs and pick.script:
                choice.notes.append(f"baking the selected {', '.join(o.name for o in highs)} onto {low.name}")
        pairs = [(low, highs)]
    for low, highs in pairs:
        # The operator's selection as it is (selected_to_active.plan sorts it out, as its poll does).
        group = [low, *highs] if pick.script else list(pick.selected)
        reason = selected_to_active.why_not(group, low, cage)
        if reason is not None:
            raise ChoiceError(reason)
        choice.targets.append(low)
        choice.sources[low.name] = group
    return choice


def _collection_pairs(pick, view_layer, cage):
    """[(low-poly, [high-poly])] of --match-collections: each low-poly ``pick.names`` names with the other
    objects with a surface in its own collections (their direct members, in name order), less the other
    low-poly objects and the cage. A low-poly whose collections hold none is an error naming it."""
    lows = _named(view_layer, pick.names, "object")
    layer = view_layer.objects
    skip = {o.name for o in lows} | ({cage.name} if cage is not None else set())
    pairs = []
    for low in lows:
        highs = sorted({o.name: o for c in low.users_collection for o in c.objects
                        if o.name not in skip and o.name in layer and o.type in GEOMETRY_TYPES}.values(),
                       key=lambda o: o.name)
        if not highs:
            where = ", ".join(repr(c.name) for c in low.users_collection) or "no collection"
            raise ChoiceError(f"{low.name} has no high-poly objects: its collection ({where}) holds no other object "
                              "with a surface to bake from")
        pairs.append((low, highs))
    return pairs


def _suffix_pairs(pick, view_layer, notes):
    """[(low-poly, [high-poly])] of --match-suffix HIGH LOW: every <base>LOW (or the named ones) with
    its <base>HIGH; a low-poly without one is skipped with a note (an error when named)."""
    high_suffix, low_suffix = pick.match_suffix
    layer = view_layer.objects
    if pick.names:
        lows = _named(view_layer, pick.names, "object")
        for obj in lows:
            if not obj.name.endswith(low_suffix):
                raise ChoiceError(f"{obj.name} does not end with the low-poly suffix {low_suffix!r}")
    else:
        lows = sorted((o for o in layer if o.name.endswith(low_suffix) and len(o.name) > len(low_suffix)),
                      key=lambda o: o.name)
    pairs = []
    for low in lows:
        name = low.name[:-len(low_suffix)] + high_suffix
        high = layer.get(name)
        if high is None:
            if pick.names:
                raise ChoiceError(f"{low.name} has no high-poly {name!r} in the view layer")
            notes.append(f"{low.name}: skipped, there is no {name}")
            continue
        pairs.append((low, [high]))
    if not pairs:
        raise ChoiceError(f"no pair of objects named <base>{high_suffix} and <base>{low_suffix} in the view layer")
    return pairs
