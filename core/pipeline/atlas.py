"""An atlas through the one pipeline: several targets baked into one image (``bake_ao([a, b, ...])``).

The steps are the pipeline's (:mod:`core.pipeline.run`), with the targets' parts side by side:

1. check: every target against the request (:func:`core.pipeline.prologue.check`), each with its own
   occluders: the other targets that occlude others (a target's ``occluding`` flag off: it occludes
   only itself; a selected-to-active target occludes through its high-poly meshes) and the
   occluders, those within reach of its surface (:func:`core.geometry.atlas.within_reach`);
2. layout: each target's tiles in its own frame, the texels it covers, who owns each texel
   (:func:`core.geometry.atlas.owners`), what each target's texels depend on (its fingerprint), and
   with ``keep`` (the record of an earlier bake) which targets must be baked again;
3. target: :class:`core.targets.atlas.AtlasBake`, a part per target baked (its own prologue, frame,
   scene and tracing, set up when its first tile comes);
4. execute: the executor, as for any bake;
5. finish: per quantity, each baked target's own denoiser and bent normals, then each texel from its
   owner (baked now, or kept from the record), the margins grown per owner into empty texels only
   (:func:`core.geometry.margin.dilate` with ``owner``), the record, the report.
"""

import dataclasses
import functools
import threading
import time
from types import SimpleNamespace

import numpy as np

from .._version import __version__
from ..base.errors import BakeCancelled, BakeMemoryError, MeshError, SettingsError
from ..base.machine import available_memory, cpu_count
from ..engine.scheduler import is_cancelled
from ..engine.settings import BakeSettings, auto_tile_shape
from ..execution.cost import bake_bytes
from ..execution.executor import bake_tiles, in_process, processes_of, worker_count
from ..files.atlasrecord import AtlasRecord
from ..geometry import atlas as A
from ..geometry.margin import dilate
from ..geometry.mesh import Mesh
from ..post import bent as bent_mod
from ..post import denoise as denoise_mod
from ..targets.atlas import AtlasBake, digest, fingerprint, occluder_digest, settings_digest
from ..targets.texels import texel_bake
from .prologue import Prologue, check, frame_of
from .remote import mesh_data
from .result import BakeReport, BakeResult, empty_reason, seam_report

#: Why a target is baked again, by what changed in its fingerprint.
_WHY = {"own": "its mesh, UVs or transform changed", "settings": "the settings changed"}


def _per_target(value, n, what):
    """A per-target argument as a list of ``n``: None for all, or a list of ``n``."""
    if value is None:
        return [None] * n
    if not isinstance(value, (list, tuple)) or len(value) != n:
        raise SettingsError(f"{what} of an atlas is a list with one entry per target ({n}), got {value!r:.80}")
    return list(value)


@dataclasses.dataclass
class Part:
    """One target of the atlas: its index, its checked input, its request (the ground resolved, its
    tiles), its normalised target, its layout (tiles without a scene) and its fingerprints."""

    index: int
    name: str
    checked: object
    request: object
    occluders: list
    reach: list
    layout: object = None
    fingerprints: dict = None
    parts: dict = None


def _check_targets(targets, occluding):
    if not targets:
        raise SettingsError("the list of targets is empty: give at least one core.Mesh")
    for t in targets:
        if not isinstance(t, Mesh):
            raise SettingsError(f"the targets must be core.Mesh objects, got {type(t).__name__}")
    names = [t.name for t in targets]
    twice = sorted({n for n in names if names.count(n) > 1})
    if twice:
        raise SettingsError(f"{len(targets)} targets, and {', '.join(map(repr, twice))} names more than one: an "
                            "atlas tells its targets apart by name (who owns a texel, what a rebake keeps); "
                            "give each a name of its own")
    occluding = [True] * len(targets) if occluding is None else [bool(o) for o in occluding]
    if len(occluding) != len(targets):
        raise SettingsError(f"occluding has {len(occluding)} entries for {len(targets)} targets")
    return names, occluding


def _surface(checked):
    """The meshes whose AO a target bakes: its high-poly meshes (selected to active), else itself."""
    return list(checked.s2a.highs) if checked.s2a is not None else [checked.target]


def _records(keep, quantities, size):
    """{quantity: AtlasRecord or None} of ``keep`` (a record, or {quantity: record})."""
    if keep is None:
        return {q: None for q in quantities}
    if isinstance(keep, AtlasRecord):
        keep = {keep.quantity: keep}
    out = {}
    for q in quantities:
        record = keep.get(q)
        if record is not None:
            if not isinstance(record, AtlasRecord):
                raise SettingsError(f"keep must be a core AtlasRecord (or one per quantity), got {type(record).__name__}")
            record.check()
        out[q] = record
    return out


def plan(request, targets, occluders, highpoly, cage, bent_space, occluding, keep):
    """Steps 1 and 2 for every target: the parts, the ownership, the fingerprints and what to bake."""
    names, occluding = _check_targets(list(targets), occluding)
    n = len(targets)
    highpoly = _per_target(highpoly, n, "highpoly")
    cage = _per_target(cage, n, "cage")
    spaces = _per_target(bent_space, n, "bent_space") if isinstance(bent_space, (list, tuple)) else [bent_space] * n
    occluders = list(occluders or ())
    for o in occluders:
        if not isinstance(o, Mesh):
            raise SettingsError(f"occluders must be core.Mesh objects, got {type(o).__name__}")
    # Checked alone first (its high-poly meshes, its cage), to know each target's surface.
    alone = [check(request, t, [], highpoly=h, cage=c, bent_space=b) for t, h, c, b in zip(targets, highpoly, cage, spaces)]
    surfaces = [_surface(c) for c in alone]
    ground = request.ground
    if ground == "auto":  # one ground under the whole atlas: its lowest baked point
        ground = min(float(m.positions[:, 2].min()) for ms in surfaces for m in ms)
    w, h = request.resolution
    quantities = request.all_quantities
    ao = "ao" in quantities
    distance = request.max_distance
    boxes = [A.bounds(ms) for ms in surfaces]
    box_of = {id(m): A.bounds([m]) for ms in surfaces for m in ms}
    box_of.update({id(o): A.bounds([o]) for o in occluders})
    parts = []
    for i, t in enumerate(targets):
        candidates = [(names[j], m) for j in range(n) if j != i and occluding[j] for m in surfaces[j]]
        candidates += [(o.name, o) for o in occluders]
        near = [(name, m) for name, m in candidates if A.within_reach(boxes[i], box_of[id(m)], distance)] if ao else []
        req = request.replace(ground=ground)
        checked = check(req, t, [m for _, m in near], highpoly=highpoly[i], cage=cage[i], bent_space=spaces[i])
        part = Part(i, names[i], checked, req, [m for _, m in near], sorted({name for name, _ in near}))
        own = digest(t, highpoly[i], cage[i], spaces[i] if request.bent_normals else None)
        occ = {}
        for name, m in near:
            occ[name] = digest(occ.get(name), occluder_digest(m)) if name in occ else occluder_digest(m)
        box = [[float(x) for x in boxes[i][0]], [float(x) for x in boxes[i][1]]]
        part.parts = {q: dict(own=own, settings=settings_digest(req, q, ground), occluders=occ if q == "ao" else {},
                              bounds=box)
                      for q in quantities}
        part.fingerprints = {q: fingerprint(p["own"], p["settings"], p["occluders"]) for q, p in part.parts.items()}
        parts.append(part)
    records = _records(keep, quantities, (w, h))
    return names, parts, records, ground


def _why(part, record, q):
    """Why ``part`` must be baked again for quantity ``q`` (``record``: the earlier bake's), or None."""
    if record is None:
        return "there is no earlier bake"
    j = record.index(part.name)
    if j is None:
        return "it is new to the atlas"
    if record.fingerprints[j] == part.fingerprints[q]:
        return None
    was = (record.extra.get("parts") or [{}] * len(record.names))[j] or {}
    now = part.parts[q]
    if was.get("own") != now["own"]:
        return _WHY["own"]
    if was.get("settings") != now["settings"]:
        return _WHY["settings"]
    before, after = was.get("occluders") or {}, now["occluders"]
    moved = sorted(k for k in set(before) | set(after) if before.get(k) != after.get(k))
    if moved:
        return f"{', '.join(moved)} within its reach changed"
    return "its fingerprint changed"


class AtlasImages:
    """One quantity's atlas, filled tile by tile: each texel from its owner's tile; with the denoiser
    each baked part's tiles are kept until the part can be filtered as a whole."""

    def __init__(self, w, h, bent, miss, owner, keep_tiles, on_tile):
        self.w, self.h = w, h
        self.owner = owner.reshape(-1)
        self.ao = np.zeros(h * w, np.float32)
        self.se = np.zeros(h * w, np.float32)
        self.count = np.zeros(h * w, np.int32)
        self.mask = np.zeros(h * w, bool)
        self.bent = np.zeros((h * w, 3), np.float32) if bent else None
        self.miss = np.zeros(h * w, bool) if miss else None
        self.tiles = {} if keep_tiles else None
        self.overlap = 0
        self.on_tile = on_tile
        self.lock = threading.Lock()

    def store(self, i, o, rect):
        t = o.texels
        own = self.owner[t] == i
        sel = t[own]
        self.ao[sel] = o.ao[own]
        self.se[sel] = o.stderr[own]
        self.count[sel] = o.samples[own]
        self.mask[sel] = ~o.lost[own]
        if o.bent is not None and self.bent is not None:
            self.bent[sel] = o.bent[own]
        if self.miss is not None:
            self.miss[sel] = o.lost[own]
        with self.lock:
            self.overlap += o.overlapping
            if self.tiles is not None:
                self.tiles.setdefault(i, []).append(o)
            if self.on_tile is not None and len(t):
                r, c, _ = rect
                self.on_tile(r, c, self.ao.reshape(self.h, self.w)[r, c].copy())


def run_atlas(request, atlas, occluders=(), *, highpoly=None, cage=None, bent_space=None, progress=None, cancel=None,
              on_tile=None, on_rays=None, remote=None):
    """Bake ``atlas`` (a :class:`core.targets.atlas.Atlas`) for ``request`` (kind 'image'): {quantity:
    BakeResult}, each with ``owner``, ``targets`` and ``record``. See :func:`core.bake_ao`. ``remote``:
    what runs tiles in other processes (:data:`core.pipeline.run.REMOTE`)."""
    targets, occluding, keep = atlas.targets, atlas.occluding, atlas.keep
    if request.kind != "image":
        raise SettingsError(f"several targets bake into one image: a bake of kind {request.kind!r} takes one target")
    t_start = time.perf_counter()
    names, parts, records, ground = plan(request, targets, occluders, highpoly, cage, bent_space, occluding, keep)
    w, h = request.resolution
    quantities = request.all_quantities
    base = request.base_quantity
    s = BakeSettings.of(request)
    n = len(parts)
    # Targets an earlier bake holds that this one does not bake: kept as they are, after the targets baked.
    held_names = []
    for r in records.values():
        if r is not None:
            if (r.width, r.height) != (w, h):
                others = [x for x in r.names if x not in names]
                if others:
                    raise SettingsError(f"the earlier atlas is {r.width} x {r.height}, this bake {w} x {h}: its "
                                        f"{', '.join(map(repr, others))} cannot be kept at another size; bake "
                                        "them too, or at the earlier size")
                records = {q: None for q in records}
                break
            held_names += [x for x in r.names if x not in names and x not in held_names]
    all_names = names + held_names
    rank = A.name_rank(all_names)
    triangles = (max(p.checked.target.triangle_count for p in parts),
                 max(sum(o.triangle_count for o in p.occluders) for p in parts),
                 max((p.checked.s2a.triangle_count if p.checked.s2a else 0) for p in parts))
    processes, per_worker = processes_of(request.workers, request.threads, s, triangles)
    if not in_process(processes) and request.tile_size is None:
        total = worker_count(processes) * per_worker
        tw, th = auto_tile_shape(w, h, 2 * total, s.samples)
        s = dataclasses.replace(s, tile_size=tw, tile_height=th, threads=min(total, cpu_count()))
    guide = request.denoise and all(p.checked.s2a is None for p in parts)
    for p in parts:  # each target's tiles in its own frame, without its scene
        shim = SimpleNamespace(target=p.checked.target.transformed(*frame_of(p.checked.target)), s2a=None,
                               bent_space=p.checked.bent_space, name=p.name)
        p.layout = texel_bake(shim, s, quantities, request.bent_normals, guide=guide)
    root = {p.index: (p.layout.lanes[base] if hasattr(p.layout, "lanes") else p.layout) for p in parts}
    coverages = [A.coverage(root[p.index].pro.target, w, h, uvtris=root[p.index].uvtris,
                            locate=p.checked.s2a is None) for p in parts]
    held = None
    held_owner = np.full(h * w, -1, np.int32)
    for r in records.values():
        if r is not None:
            for x in held_names:
                j = r.index(x)
                if j is not None:
                    held_owner[r.owner.reshape(-1) == j] = all_names.index(x)
    if held_names:
        held = (held_owner >= 0).reshape(h, w)
    own = A.owners(coverages, rank[:n], w, h, held=held)
    owner = own.owner.reshape(-1).copy()
    owner[held_owner >= 0] = held_owner[held_owner >= 0]
    # What to bake: each target whose fingerprint changed for some quantity, or that now owns texels
    # the earlier bake gave another.
    why, todo = {}, []
    for p in parts:
        reasons = [r for r in (_why(p, records[q], q) for q in quantities) if r]
        if not reasons:
            for q in quantities:
                r = records[q]
                j = r.index(p.name)
                mine = np.flatnonzero(owner == p.index)
                if not np.all(r.owner.reshape(-1)[mine] == j):
                    reasons.append("texels it shares with another target changed hands")
                    break
        if reasons:
            why[p.name] = reasons[0]
            todo.append(p.index)
    unlimited = not np.isfinite(request.max_distance) and "ao" in quantities and n > 1
    stale = _stale_held(parts, todo, records, held_names, request.max_distance) if "ao" in quantities else []
    memory_check(parts, todo, s)
    if is_cancelled(cancel):
        raise BakeCancelled("the bake was cancelled before it started")

    images = {q: AtlasImages(w, h, request.bent_normals and q == "ao", any(p.checked.s2a for p in parts), owner,
                             request.denoise, None if on_tile is None else on_tile if request.quantities is None
                             else functools.partial(on_tile, q))
              for q in quantities}
    keys = [(i, k) for i in todo for k in sorted(root[i].bins)]
    planned = sum(parts[i].layout.planned for i in todo)
    by_index = {p.index: p for p in parts}

    def build(i):
        p = by_index[i]
        pro = Prologue(p.checked, p.request.replace(tile_size=root[i].s.tile_shape), cancel)
        return texel_bake(pro, root[i].s, quantities, request.bent_normals, guide=guide)

    bake = AtlasBake(build, s, planned, layouts={i: parts[i].layout for i in todo},
                     tiles={i: len(root[i].bins) for i in todo}, keep_live=s.threads + 1)

    def store(out):
        i = out.key[0]
        layout = parts[i].layout
        outs = layout.outs(out) if hasattr(layout, "outs") else {base: out}
        for q, o in outs.items():
            lane = layout.lanes[q] if hasattr(layout, "lanes") else layout
            if o.sums is not None:
                lane.directions(o)
            images[q].store(i, o, lane.rect(out.key[1]))

    def job():
        return atlas_job(parts, todo, root, request, guide)

    if keys:
        rays, trace_s, trace_cpu, counters, fallback = bake_tiles(remote, bake, keys, processes, per_worker, job, store,
                                                                  progress, cancel, on_rays)
    else:
        rays, trace_s, trace_cpu, counters, fallback = 0, 0.0, 0.0, {}, None
        if progress is not None:
            progress(1.0)
    results = {}
    for q in quantities:
        results[q] = finish(q, images[q], parts, todo, records[q], all_names, held_names, rank, owner, own, s,
                            request, ground, why, unlimited, counters, rays, trace_s, trace_cpu, fallback, t_start,
                            lambda i: images[base].tiles.get(i, []))
        if stale and q == "ao":
            results[q].report.warn(*stale)
    return results


def _stale_held(parts, todo, records, held_names, distance):
    """Warnings for the targets an earlier bake holds and this one does not bake, within reach of a
    target baked now (where it is, or where it was): their texels are kept as they were, and no longer
    what a bake of them would give."""
    record = records.get("ao")
    if record is None or not held_names:
        return []
    was = record.extra.get("parts") or [{}] * len(record.names)
    out = []
    for name in held_names:
        j = record.index(name)
        held = (was[j] or {}).get("bounds") if j is not None else None
        if held is None:
            continue
        near = []
        for i in todo:
            k = record.index(parts[i].name)
            boxes = [parts[i].parts["ao"]["bounds"]] + ([was[k]["bounds"]] if k is not None and (was[k] or {}).get("bounds")
                                                        else [])
            if any(A.within_reach(np.asarray(held), np.asarray(b), distance) for b in boxes):
                near.append(parts[i].name)
        if near:
            out.append(f"{name} was not baked now, and {', '.join(near)} within its reach changed: its texels are "
                       f"those of its earlier bake; bake {name} too for them to follow")
    return out


def memory_check(parts, todo, s):
    """Refuse an atlas whose largest part would not fit in the memory available (BakeMemoryError)."""
    if not todo:
        return
    counts = [(parts[i].checked.target.triangle_count, sum(o.triangle_count for o in parts[i].occluders),
               parts[i].checked.s2a.triangle_count if parts[i].checked.s2a else 0) for i in todo]
    largest = max(counts, key=sum)
    tri = sum(largest)
    need = bake_bytes(s.width, s.height, largest, s.threads, s.chunk_rays, s.samples, s.source, s.replicates,
                      s.tile_shape[0] * s.tile_shape[1])
    avail = available_memory()
    if avail is not None and need > avail:
        raise BakeMemoryError(f"a {s.width} x {s.height} atlas whose largest part holds {tri} triangles needs about "
                              f"{need / 2**30:.2f} GiB, but only {avail / 2**30:.2f} GiB is available; lower the "
                              "resolution")


def atlas_job(parts, todo, root, request, guide):
    """What a worker process rebuilds the atlas's parts from: every mesh once, and each part's target,
    occluders, high-poly meshes, cage and tiles as indices into them."""
    meshes, index = [], {}

    def ref(m):
        if m is None:
            return None
        if id(m) not in index:
            index[id(m)] = len(meshes)
            meshes.append(mesh_data(m))
        return index[id(m)]

    plain = {}
    for i in todo:
        p = parts[i]
        c = p.checked
        plain[i] = dict(target=ref(c.target), occluders=[ref(o) for o in c.occluders],
                        highpoly=None if c.s2a is None else [ref(m) for m in c.s2a.highs],
                        cage=None if c.s2a is None or c.s2a.cage is None else ref(c.s2a.cage),
                        tile=list(root[i].s.tile_shape))
    return dict(kind="atlas", request=parts[todo[0]].request.to_dict(), meshes=meshes, parts=plain,
                planned=sum(parts[i].layout.planned for i in todo), guide=guide)


def finish(q, img, parts, todo, record, all_names, held_names, rank, owner, own, s, request, ground, why, unlimited,
           counters, rays, trace_s, trace_cpu, fallback, t_start, guide_tiles):
    """Quantity ``q``'s BakeResult of the atlas: the baked parts' denoiser, the kept texels, the
    record, the margins per owner, the bent normals, metadata and report."""
    w, h = s.width, s.height
    n = len(parts)
    ls = BakeSettings.of(request, q)
    raw_ao = raw_se = None
    if request.denoise:
        raw_ao, raw_se = img.ao.copy(), img.se.copy()
        for i in todo:
            _denoise_part(img, i, parts[i], ls, request, guide_tiles(i))
    # Texels kept from the earlier bake: every target not baked now, and the targets it held that
    # this bake does not name.
    kept = [p.index for p in parts if p.index not in todo]
    if record is not None:
        rec_owner = record.owner.reshape(-1)
        covered = record.covered
        for k, name in enumerate(all_names):
            if k < n and k not in kept:
                continue
            j = record.index(name)
            if j is None:
                continue
            mine = np.flatnonzero(owner == k)
            pos = np.searchsorted(covered, mine)
            ok = (pos < len(covered)) & (rec_owner[mine] == j)
            mine, pos = mine[ok], pos[ok]
            img.ao[mine], img.se[mine], img.count[mine] = record.ao[pos], record.stderr[pos], record.samples[pos]
            img.mask[mine] = record.mask[pos] if record.mask is not None else True
            if img.bent is not None and record.bent is not None:
                img.bent[mine] = record.bent[pos]
            if raw_ao is not None:
                raw_ao[mine] = record.raw_ao[pos] if record.raw_ao is not None else record.ao[pos]
                raw_se[mine] = record.raw_stderr[pos] if record.raw_stderr is not None else record.stderr[pos]
    owned = np.flatnonzero(owner >= 0)
    fps = [p.fingerprints[q] for p in parts]
    if record is not None:
        fps += [record.fingerprints[record.index(x)] if record.index(x) is not None else "" for x in held_names]
    part_digests = [p.parts[q] for p in parts]
    if record is not None:
        was = record.extra.get("parts") or [{}] * len(record.names)
        part_digests += [was[record.index(x)] if record.index(x) is not None else {} for x in held_names]
    new_record = AtlasRecord(w, h, tuple(all_names), tuple(fps), owner.reshape(h, w).astype(np.int32),
                             img.ao[owned].copy(), img.se[owned].copy(), img.count[owned].copy(), img.mask[owned].copy(),
                             None if raw_ao is None else raw_ao[owned].copy(),
                             None if raw_se is None else raw_se[owned].copy(),
                             None if img.bent is None else img.bent[owned].copy(), quantity=q,
                             extra=dict(parts=part_digests, ground=ground))
    mask2 = img.mask.reshape(h, w)
    covered_owner = np.where(img.mask, owner, -1).astype(np.int32).reshape(h, w)
    out_owner = covered_owner.copy()
    ao2 = img.ao.reshape(h, w)
    if s.margin > 0:
        dilate(ao2, mask2, s.margin, threads=s.threads, out=ao2, owner=out_owner, rank=rank)
        if raw_ao is not None:
            r2 = raw_ao.reshape(h, w)
            dilate(r2, mask2, s.margin, threads=s.threads, out=r2, owner=covered_owner.copy(), rank=rank)
    se2 = img.se.reshape(h, w)
    fix = None
    if request.fix_seams:  # after the margins, over the whole image, each seam its target's
        from ..post.fixseams import fix_baked

        fix = fix_baked([p.checked.target for p in parts], ao2, se2, mask2, owner=out_owner)
    bent = None
    if img.bent is not None:
        bent, _ = bent_mod.dilate_directions(img.bent.reshape(h, w, 3), mask2, s.margin, s.threads,
                                             owner=covered_owner, rank=rank)
    metadata = dict(ls.metadata(ls.max_distance), version=__version__, rays=_rays(counters, q, rays),
                    atlas_targets=len(all_names))
    if request.quantities is not None:
        metadata["quantities"] = ",".join(request.all_quantities)
    if request.denoise:
        metadata["denoise"] = True
    if fix is not None:
        metadata["fix_seams"] = True
    if ground is not None:
        metadata["ground_height"] = ground
    baked = [parts[i].name for i in todo]
    report = BakeReport(covered_texels=int(img.mask.sum()), overlapping_texels=img.overlap,
                        degenerate_uv_triangles=sum(parts[i].layout.uvtris.degenerate for i in range(n)),
                        degenerate_triangles=sum(parts[i].layout.uvtris.degenerate_space for i in range(n)),
                        uv_outside_triangles=sum(parts[i].layout.uvtris.outside for i in range(n)),
                        worker_memory=counters.get("worker_memory", []),
                        atlas={"targets": list(all_names), "baked": baked,
                        "kept": [p.name for p in parts if p.index not in todo] + list(held_names),
                        "held": list(held_names),
                        "why": {name: why[name] for name in baked},
                        "reach": {p.name: p.reach for p in parts},
                        "owned": {name: int(np.count_nonzero(owner == k)) for k, name in enumerate(all_names)},
                        "shared_texels": own.shared, "unlimited_reach": bool(unlimited)},
                        atlas_overlaps=[{"a": all_names[i], "b": all_names[j], "texels": c}
                                        for i, j, c in own.overlaps], **seam_report(fix))
    warnings = []
    for k, name in enumerate(all_names[:n]):
        if not own.covered[k]:
            warnings.append(f"{name!r} covers no texel of the {w} x {h} atlas ("
                            f"{empty_reason(parts[k].layout.uvtris.degenerate_space, parts[k].layout.uvtris.degenerate, parts[k].layout.uvtris.outside)})")
    if unlimited:
        report.atlas["note"] = ("with an unlimited distance every target can occlude every other: a change to one "
                                "bakes them all again")
    if fallback is not None:
        warnings.append(f"baked on {s.threads} threads of this process, not in worker processes: {fallback}")
    if warnings:
        report.warn(*warnings)
    if not img.mask.any() and not request.empty_ok:
        raise MeshError(f"the atlas of {', '.join(map(repr, all_names))} covered no texel of the {w} x {h} image: "
                        "nothing was written")
    seconds = time.perf_counter() - t_start
    return BakeResult(ao=ao2, mask=mask2, stderr=se2, samples=img.count.reshape(h, w),
                      rays=_rays(counters, q, rays), seconds=seconds, trace_seconds=trace_s, threads=s.threads,
                      metadata=metadata, report=report, trace_cpu_seconds=trace_cpu, bent=bent,
                      miss=None if img.miss is None else img.miss.reshape(h, w),
                      raw_ao=None if raw_ao is None else raw_ao.reshape(h, w),
                      raw_stderr=None if raw_se is None else raw_se.reshape(h, w),
                      owner=out_owner, targets=tuple(all_names), record=new_record)


def _rays(counters, q, rays):
    """The rays of quantity ``q``: a bake of several quantities counts each lane's (summed over parts)."""
    total = 0
    found = False
    for k, v in counters.items():
        if isinstance(v, dict) and isinstance(v.get(q), dict) and "rays" in v[q]:
            total += v[q]["rays"]
            found = True
    return total if found else rays


def _denoise_part(img, i, part, ls, request, guide_tiles):
    """Filter part ``i``'s estimate over its own surface (its tiles, every texel it covers, owned or not),
    and take its owned texels from the filtered map. ``guide_tiles``: the part's tiles of the base
    quantity, which carry the denoiser's guide (as a bake of one target hands it to every quantity)."""
    w, h = ls.width, ls.height
    tiles = img.tiles.get(i, []) if img.tiles is not None else []
    if not tiles:
        return
    ao, se = np.zeros(h * w, np.float32), np.zeros(h * w, np.float32)
    mask = np.zeros(h * w, bool)
    for o in tiles:
        t = o.texels
        ao[t], se[t], mask[t] = o.ao, o.stderr, ~o.lost
    gtri, gpoint, gnormal = np.full(h * w, -1, np.int32), np.zeros((h * w, 3), np.float32), np.zeros((h * w, 3), np.float32)
    have_guide = False
    for o in guide_tiles:
        if o.guide is not None:
            have_guide = True
            t = o.texels
            gtri[t], gpoint[t], gnormal[t] = o.guide
    layout = part.layout.lanes[request.base_quantity] if hasattr(part.layout, "lanes") else part.layout
    guide = denoise_mod.surface_guide(layout.pro.target, (w, h), texels=(gtri, gpoint, gnormal) if have_guide else None,
                                      tris=layout.uvtris)
    dn, dse, _ = denoise_mod.denoise(ao.reshape(h, w), se.reshape(h, w), mask.reshape(h, w), guide, threads=ls.threads)
    mine = np.flatnonzero(img.owner == i)
    img.ao[mine] = dn.reshape(-1)[mine]
    img.se[mine] = dse.reshape(-1)[mine]



# -- UDIM tiles -------------------------------------------------------------------------------------------

def run_udim_atlas(request, atlas, occluders=(), *, highpoly=None, cage=None, bent_space=None, progress=None,
                   cancel=None, on_tile=None, on_rays=None, remote=None):
    """An atlas over UDIM tiles (``request.kind`` 'udim'): every tile an atlas of its own, of the
    targets whose UVs reach it (the others occlude as meshes), with its own seed, then each quantity's
    tiles stacked: ``owner`` (N, H, W) indexes ``targets`` (every target of the list, then those an
    earlier bake held); ``record`` {tile: AtlasRecord}; ``tiles`` {tile: the tile's result}.
    ``atlas.keep``: {tile: record (or {quantity: record})} of an earlier bake. Not with ``denoise``:
    a target's tiles would each be filtered alone, not across the tiles' seams as one target's are."""
    from ..geometry.uvtiles import covered_tiles, shifted, tile_seed
    from ..targets.atlas import Atlas

    if request.denoise:
        raise SettingsError("an atlas over UDIM tiles is not denoised: each target's tiles would be filtered "
                            "apart, not across the tiles' seams as one target's are; bake it without denoise")
    targets = list(atlas.targets)
    names, occluding = _check_targets(targets, atlas.occluding)
    n = len(targets)
    highpoly = _per_target(highpoly, n, "highpoly")
    cage = _per_target(cage, n, "cage")
    coverage = [covered_tiles(t, request.resolution) for t in targets]
    todo = sorted(set().union(*[c.tiles for c in coverage])) if request.tiles is None else list(request.tiles)
    keep = atlas.keep or {}
    weight = np.array([sum(c.area.get(t, 0.0) for c in coverage) for t in todo]) + 1e-12
    weight /= weight.sum()
    done = np.concatenate([[0.0], np.cumsum(weight)])
    # Fix Seams once over every tile, after they are stacked: the tiles' shared edges too, and a tile's
    # own bake would look up the seams of the targets' other tiles in its image.
    tile_request = request.replace(kind="image", tiles=None, empty_ok=True, fix_seams=False)
    quantities = request.all_quantities
    maps = request.quantities is not None
    results = {q: {} for q in quantities}
    for k, tile in enumerate(todo):
        here = [i for i in range(n) if tile in coverage[i].tiles]
        if not here:  # a tile asked for that no target reaches: baked empty, as a target's would be
            here = [0]
        away = [m for i in range(n) if i not in here and occluding[i]
                for m in (list(highpoly[i]) if isinstance(highpoly[i], (list, tuple)) else
                          [highpoly[i]] if highpoly[i] is not None else [targets[i]])]

        def tile_progress(f, k=k):
            if progress is not None:
                progress(min(done[k] + weight[k] * f, 1.0))

        def tile_block(*args, tile=tile):
            if not maps:
                on_tile(tile, *args)
            else:
                on_tile(args[0], tile, *args[1:])

        part = Atlas([shifted(targets[i], tile) for i in here], occluding=[occluding[i] for i in here],
                     keep=keep.get(tile))
        baked = run_atlas(tile_request.replace(seed=tile_seed(request.seed, tile)), part, list(occluders or ()) + away,
                          highpoly=None if all(h is None for h in highpoly) else [highpoly[i] for i in here],
                          cage=None if all(c is None for c in cage) else [cage[i] for i in here],
                          bent_space=bent_space if not isinstance(bent_space, (list, tuple))
                          else [bent_space[i] for i in here], progress=tile_progress, cancel=cancel,
                          on_tile=None if on_tile is None else tile_block, on_rays=on_rays, remote=remote)
        for q in quantities:
            results[q][tile] = baked[q]
    return {q: _stack_tiles(results[q], names, todo, coverage, targets if request.fix_seams else None)
            for q in quantities}


def _stack_tiles(results, names, todo, coverage, fix_targets=None):
    """One quantity's UDIM atlas from its tiles' atlases: the planes stacked, the owner maps indexing
    one list of names, the reports merged; with ``fix_targets`` (the targets, in the order of
    ``names``) the seams fixed over all the tiles at once."""
    all_names = list(names)
    for r in results.values():
        all_names += [x for x in r.targets if x not in all_names]
    owners = []
    for r in results.values():
        remap = np.array([all_names.index(x) for x in r.targets] + [-1], np.int32)
        owners.append(np.where(r.owner >= 0, remap[r.owner], -1).astype(np.int32))
    parts = list(results.values())

    def stack(name):
        return np.stack([getattr(r, name) for r in parts])

    fix = None
    if fix_targets is not None:
        from ..post.fixseams import fix_baked

        ao, se = stack("ao"), stack("stderr")
        fix = fix_baked(list(fix_targets), ao, se, stack("mask"), tiles=list(results), owner=np.stack(owners))
        for i, r in enumerate(parts):
            r.ao, r.stderr = ao[i], se[i]
            r.metadata["fix_seams"] = True

    report = BakeReport(covered_texels=sum(r.report.covered_texels or 0 for r in parts),
                        overlapping_texels=sum(r.report.overlapping_texels or 0 for r in parts),
                        degenerate_uv_triangles=parts[0].report.degenerate_uv_triangles,
                        degenerate_triangles=parts[0].report.degenerate_triangles,
                        uv_outside_udim_triangles=sum(c.outside for c in coverage), tiles=list(todo),
                        worker_memory=parts[0].report.worker_memory,
                        atlas={"targets": all_names,
                               "baked": [x for x in all_names if any(x in r.report.atlas["baked"] for r in parts)],
                               "kept": [x for x in all_names if all(x not in r.report.atlas["baked"] for r in parts)],
                               "tiles": {t: r.report.atlas for t, r in results.items()}},
                        atlas_overlaps=[dict(o, tile=t) for t, r in results.items()
                                        for o in (r.report.atlas_overlaps or [])], **seam_report(fix))
    warnings = [w for r in parts for w in (r.report.warnings or []) if "covers no texel" not in w]
    if warnings:
        report.warn(*dict.fromkeys(warnings))
    if not any(r.mask.any() for r in parts):
        raise MeshError(f"the atlas of {', '.join(map(repr, names))} covered no texel of the UDIM tiles "
                        f"{', '.join(map(str, todo))}: nothing was written")
    return BakeResult(ao=stack("ao"), mask=stack("mask"), stderr=stack("stderr"), samples=stack("samples"),
                      rays=sum(r.rays for r in parts), seconds=sum(r.seconds for r in parts),
                      trace_seconds=sum(r.trace_seconds for r in parts), threads=parts[0].threads,
                      trace_cpu_seconds=sum(r.trace_cpu_seconds for r in parts), metadata=dict(parts[0].metadata),
                      report=report, tiles=results, bent=stack("bent") if parts[0].bent is not None else None,
                      owner=np.stack(owners), targets=tuple(all_names),
                      record={t: r.record for t, r in results.items()})


__all__ = ["run_atlas", "run_udim_atlas", "plan", "atlas_job"]
