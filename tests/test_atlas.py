"""Atlases: several targets baked into one image (core.bake_ao([a, b, ...]), core.Atlas).

What is pinned here: who owns a shared texel (more area, then the name, never the list's order);
overlaps reported per pair; margins that never reach another target's covered texels and grow per
owner (one owner: the bits of the plain margin); each target's texels the bits of baking it alone
with the others as occluders, and within 3 standard errors of such a bake with another seed; the
same bits for any threads, processes and tiling; a rebake that keeps the texels of every target whose
fingerprint did not change and gives the bits of a full bake (ten objects, one moved: exactly the
objects within its reach are baked again); the record's round trip and its refusals.
"""

import numpy as np
import pytest

import core
from core import Atlas, AtlasRecord, Mesh, SettingsError, bake_ao, bake_maps
from core.files.atlasrecord import sidecar_path
from core.geometry import atlas as A
from core.geometry.margin import dilate

KW = dict(resolution=64, samples=16, seed=5, margin=4, threads=2)


def quad(name, x0, y0, z, size, uv0, uv1, down=False):
    """A square of side ``size`` at height ``z`` (facing +z, or -z with ``down``), its UVs the
    rectangle uv0 .. uv1."""
    P = np.array([[x0, y0, z], [x0 + size, y0, z], [x0 + size, y0 + size, z], [x0, y0 + size, z]], float)
    F = np.array([[0, 1, 2], [0, 2, 3]])
    (u0, v0), (u1, v1) = uv0, uv1
    uv = np.array([[u0, v0], [u1, v0], [u1, v1], [u0, v1]], float)
    if down:
        F = F[:, ::-1]
    return Mesh(P, F, uvs=uv[F], name=name)


def box(name, centre, half, slot, slots=(5, 2)):
    """An axis-aligned box (12 triangles, outward winding), its six faces laid out 3 x 2 inside UV slot
    ``slot`` of a ``slots`` grid (each face inset so that no texel is shared)."""
    c, hx = np.asarray(centre, float), float(half)
    corners = np.array([[x, y, z] for z in (-1, 1) for y in (-1, 1) for x in (-1, 1)], float) * hx + c
    faces = [(0, 2, 3, 1), (4, 5, 7, 6), (0, 1, 5, 4), (2, 6, 7, 3), (0, 4, 6, 2), (1, 3, 7, 5)]
    sx, sy = 1.0 / slots[0], 1.0 / slots[1]
    ox, oy = (slot % slots[0]) * sx, (slot // slots[0]) * sy
    F, UV = [], []
    for k, (a, b, cc, d) in enumerate(faces):
        fx, fy = k % 3, k // 3
        u0, v0 = ox + (fx + 0.1) * sx / 3, oy + (fy + 0.1) * sy / 2
        u1, v1 = ox + (fx + 0.9) * sx / 3, oy + (fy + 0.9) * sy / 2
        quv = np.array([[u0, v0], [u1, v0], [u1, v1], [u0, v1]])
        for tri in ((0, 1, 2), (0, 2, 3)):
            F.append([(a, b, cc, d)[t] for t in tri])
            UV.append(quv[list(tri)])
    return Mesh(corners, np.array(F), uvs=np.array(UV), name=name)


def scene():
    floor = quad("Floor", -1, -1, 0.0, 2, (0.0, 0.0), (0.5, 0.5))
    lid = quad("Lid", -0.5, -0.5, 0.3, 1, (0.5, 0.0), (1.0, 0.5), down=True)
    post = box("Post", (0.6, 0.6, 0.2), 0.15, 5)
    return [floor, lid, post]


def test_each_target_is_its_bake_alone_with_the_others_as_occluders():
    """Bit for bit (same seed), and within 3 standard errors of the mean over its texels (another seed)."""
    targets = scene()
    r = bake_ao(targets, [], **KW)
    assert r.targets == ("Floor", "Lid", "Post") and r.owner.dtype == np.int32 and r.owner.shape == (64, 64)
    for i, t in enumerate(targets):
        others = [o for o in targets if o is not t]
        alone = bake_ao(t, others, **KW)
        mine = r.mask & (r.owner == i)
        assert mine.sum() > 100
        for name in ("ao", "stderr", "samples"):
            np.testing.assert_array_equal(getattr(r, name)[mine], getattr(alone, name)[mine], err_msg=t.name)
        other = bake_ao(t, others, **dict(KW, seed=991, samples=64))
        d = r.ao[mine].astype(float) - other.ao[mine]
        se = np.sqrt(np.sum(r.stderr[mine].astype(float) ** 2 + other.stderr[mine].astype(float) ** 2)) / mine.sum()
        assert abs(d.mean()) <= 3 * se, (t.name, d.mean(), se)


def test_a_shared_texel_goes_to_more_area_then_to_the_first_name_never_the_list_order():
    w = 16
    # "B" (listed first) covers the left of column 8 up to a fraction f of it, "A" the rest.
    for f, want in ((0.3, "A"), (0.7, "B"), (0.5, "A")):
        cut = (8 + f) / w
        b = quad("B", 0, 0, 0, 1, (0.0, 0.0), (cut, 1.0))
        a = quad("A", 2, 0, 0, 1, (cut, 0.0), (1.0, 1.0))
        r = bake_ao([b, a], [], resolution=w, samples=4, margin=0, threads=1)
        col = r.owner[:, 8]
        assert set(col.tolist()) == {r.targets.index(want)}, (f, col)
        assert r.report["atlas"]["shared_texels"] == w
        assert r.report["atlas_overlaps"] == []


def test_overlapping_uvs_are_reported_per_pair_with_their_texels():
    w = 32
    a = quad("A", 0, 0, 0, 1, (0.0, 0.0), (0.5, 1.0))
    b = quad("B", 2, 0, 0, 1, (0.25, 0.0), (0.75, 1.0))  # over A's right half
    c = quad("C", 4, 0, 0, 1, (0.5, 0.0), (1.0, 1.0))  # over B's right half, beside A
    r = bake_ao([c, b, a], [], resolution=w, samples=4, margin=0, threads=1)
    pairs = {(o["a"], o["b"]): o["texels"] for o in r.report["atlas_overlaps"]}
    assert pairs == {("A", "B"): 8 * w, ("B", "C"): 8 * w}
    # the same rule in the overlaps: equal areas, the first by name
    idx = {name: k for k, name in enumerate(r.targets)}
    assert np.all(r.owner[:, 8:16] == idx["A"]) and np.all(r.owner[:, 16:24] == idx["B"])


def test_margins_never_reach_another_targets_covered_texels_and_grow_per_owner():
    targets = scene()
    none = bake_ao(targets, [], **dict(KW, margin=0))
    r = bake_ao(targets, [], **dict(KW, margin=8))
    covered = none.mask
    np.testing.assert_array_equal(r.mask, covered)
    np.testing.assert_array_equal(r.ao[covered], none.ao[covered])  # no covered texel changed
    np.testing.assert_array_equal(r.owner[covered], none.owner[covered])
    margin = (r.owner >= 0) & ~covered
    assert margin.any()
    # every margin texel touches a texel of its own owner (the rings grow per owner)
    pad = np.pad(r.owner, 1, constant_values=-1)
    ys, xs = np.nonzero(margin)
    own = r.owner[ys, xs]
    near = np.zeros(len(ys), bool)
    for dy in (-1, 0, 1):
        for dx in (-1, 0, 1):
            if dy or dx:
                near |= pad[ys + 1 + dy, xs + 1 + dx] == own
    assert near.all()


def test_one_owner_margin_is_the_plain_margin_bit_for_bit():
    rng = np.random.default_rng(7)
    mask = np.zeros((90, 70), bool)
    for _ in range(12):
        y, x = rng.integers(0, 90), rng.integers(0, 70)
        mask[y:y + rng.integers(2, 20), x:x + rng.integers(2, 20)] = True
    values = rng.random((90, 70)).astype(np.float32)
    owner = np.where(mask, 0, -1).astype(np.int32)
    for threads in (1, 3):
        np.testing.assert_array_equal(dilate(values, mask, 6, threads=threads),
                                      dilate(values, mask, 6, threads=threads, owner=owner.copy()))
    # two owners: a texel of one target's margin never takes the other's values, whatever the threads
    two = np.where(mask, (np.arange(70)[None, :] >= 35).astype(np.int32), -1).astype(np.int32)
    o1, o3 = two.copy(), two.copy()
    a = dilate(values, mask, 6, threads=1, owner=o1)
    np.testing.assert_array_equal(a, dilate(values, mask, 6, threads=3, owner=o3))
    np.testing.assert_array_equal(o1, o3)
    moved = values + np.where(two == 1, 0.5, 0.0).astype(np.float32)
    b = dilate(moved, mask, 6, owner=two.copy())
    sel = (o1 == 0) & ~mask
    np.testing.assert_array_equal(a[sel], b[sel])


@pytest.mark.parametrize("how", [dict(threads=1), dict(threads=2, tile_size=16), dict(workers=2, threads=1)],
                         ids=["1 thread", "2 threads 16^2 tiles", "2 processes"])
def test_the_same_bits_for_any_threads_processes_and_tiling(how):
    targets = scene()
    ref = bake_ao(targets, [], **dict(KW, threads=2))
    r = bake_ao(targets, [], **dict(KW, **how))
    for name in ("ao", "stderr", "samples", "mask", "owner"):
        np.testing.assert_array_equal(getattr(r, name), getattr(ref, name), err_msg=name)


@pytest.mark.parametrize("extra", [dict(denoise=True), dict(bent_normals=True), dict(target_error=0.05),
                                   dict(quantity="thickness", max_distance=0.5)],
                         ids=["denoise", "bent normals", "adaptive", "thickness"])
def test_denoise_bent_normals_adaptive_and_thickness_as_for_one_target(extra):
    targets = scene()
    kw = dict(KW, **extra)
    r = bake_ao(targets, [], **kw)
    for i, t in enumerate(targets):
        alone = bake_ao(t, [o for o in targets if o is not t], **kw)
        mine = r.mask & (r.owner == i)
        np.testing.assert_array_equal(r.ao[mine], alone.ao[mine], err_msg=t.name)
        np.testing.assert_array_equal(r.stderr[mine], alone.stderr[mine], err_msg=t.name)
        if extra.get("bent_normals"):
            np.testing.assert_array_equal(r.bent[mine], alone.bent[mine], err_msg=t.name)
        if extra.get("denoise"):
            np.testing.assert_array_equal(r.raw_ao[mine], alone.raw_ao[mine], err_msg=t.name)
    again = bake_ao(Atlas(targets, keep=r.record), [], **kw)
    assert again.report["atlas"]["baked"] == [] and again.report["atlas"]["kept"] == ["Floor", "Lid", "Post"]
    for name in ("ao", "stderr", "samples", "mask", "owner", "bent", "raw_ao"):
        if getattr(r, name) is not None:
            np.testing.assert_array_equal(getattr(again, name), getattr(r, name), err_msg=name)


def test_maps_of_an_atlas_are_each_quantitys_atlas():
    targets = scene()
    m = bake_maps(targets, [], **KW)
    for q in ("ao", "thickness"):
        one = bake_ao(targets, [], quantity=q, **KW)
        np.testing.assert_array_equal(m[q].ao, one.ao)
        np.testing.assert_array_equal(m[q].owner, one.owner)
    again = bake_maps(Atlas(targets, keep={q: m[q].record for q in m}), [], **KW)
    assert again["ao"].report["atlas"]["baked"] == []
    np.testing.assert_array_equal(again["thickness"].ao, m["thickness"].ao)


def test_a_target_that_does_not_occlude_others_occludes_only_itself():
    targets = scene()
    r = bake_ao(Atlas(targets, occluding=[True, False, True]), [], **KW)
    floor = bake_ao(targets[0], [targets[2]], **KW)  # the lid is not over it
    mine = r.mask & (r.owner == 0)
    np.testing.assert_array_equal(r.ao[mine], floor.ao[mine])
    assert r.report["atlas"]["reach"]["Floor"] == ["Post"]


def ten_boxes(moved=None, dx=0.05):
    boxes = []
    for k in range(10):
        x = k * 1.0 + (dx if k == moved else 0.0)
        boxes.append(box(f"Box{k}", (x, 0.0, 0.2), 0.2, k))
    return boxes


def test_ten_objects_one_moved_rebakes_exactly_those_within_its_reach_and_equals_a_full_bake():
    kw = dict(resolution=(160, 64), samples=8, seed=2, margin=3, threads=2, max_distance=0.7)
    first = bake_ao(ten_boxes(), [], **kw)
    assert first.report["atlas"]["reach"]["Box5"] == ["Box4", "Box6"]
    partial = bake_ao(Atlas(ten_boxes(moved=5), keep=first.record), [], **kw)
    full = bake_ao(ten_boxes(moved=5), [], **kw)
    report = partial.report["atlas"]
    assert report["baked"] == ["Box4", "Box5", "Box6"]
    assert report["why"] == {"Box4": "Box5 within its reach changed", "Box5": "its mesh, UVs or transform changed",
                             "Box6": "Box5 within its reach changed"}
    assert sorted(report["kept"]) == sorted(f"Box{k}" for k in range(10) if k not in (4, 5, 6))
    for name in ("ao", "stderr", "samples", "mask", "owner"):
        np.testing.assert_array_equal(getattr(partial, name), getattr(full, name), err_msg=name)
    assert partial.record.to_bytes() == full.record.to_bytes()
    # An occluder that moves away counts too: Box6 moved out of Box5's reach bakes Box5 again.
    away = ten_boxes()
    away[6] = box("Box6", (6.6, 0.0, 0.2), 0.2, 6)
    r = bake_ao(Atlas(away, keep=first.record), [], **kw)
    assert r.report["atlas"]["baked"] == ["Box5", "Box6", "Box7"]


def test_with_an_unlimited_distance_every_target_depends_on_every_other():
    kw = dict(resolution=(160, 64), samples=4, seed=2, margin=2, threads=2)
    first = bake_ao(ten_boxes(), [], **kw)
    r = bake_ao(Atlas(ten_boxes(moved=9), keep=first.record), [], **kw)
    assert r.report["atlas"]["unlimited_reach"] and "every target can occlude every other" in r.report["atlas"]["note"]
    assert r.report["atlas"]["baked"] == [f"Box{k}" for k in range(10)]
    unchanged = bake_ao(Atlas(ten_boxes(), keep=first.record), [], **kw)
    assert unchanged.report["atlas"]["baked"] == []


def test_targets_an_earlier_bake_held_are_kept_and_a_size_change_that_would_lose_them_is_refused():
    targets = scene()
    r = bake_ao(targets, [], **KW)
    only_lid = bake_ao(Atlas([targets[1]], keep=r.record), [targets[0], targets[2]], **KW)
    assert only_lid.targets == ("Lid", "Floor", "Post")
    assert only_lid.report["atlas"]["kept"] == ["Lid", "Floor", "Post"]
    np.testing.assert_array_equal(only_lid.ao, r.ao)
    with pytest.raises(SettingsError, match=r"earlier atlas is 64 x 64, this bake 32 x 32: its 'Floor', 'Post' "
                                            r"cannot be kept"):
        bake_ao(Atlas([targets[1]], keep=r.record), [], **dict(KW, resolution=32))


def test_the_record_round_trips_and_a_damaged_one_is_refused(tmp_path):
    r = bake_ao(scene(), [], **KW)
    data = r.record.to_bytes()
    back = AtlasRecord.from_bytes(data)
    assert back.names == r.record.names and back.fingerprints == r.record.fingerprints
    np.testing.assert_array_equal(back.owner, r.record.owner)
    path = tmp_path / "Atlas.png"
    side = sidecar_path(path)
    assert side.endswith("Atlas.atlas.npz")
    r.record.write(side)
    assert AtlasRecord.read(side).to_bytes() == data
    assert AtlasRecord.read(tmp_path / "none.atlas.npz") is None
    (tmp_path / "bad.atlas.npz").write_bytes(data[: len(data) // 2])
    with pytest.raises(SettingsError, match="cannot be read as an atlas record"):
        AtlasRecord.read(tmp_path / "bad.atlas.npz")
    back.ao = back.ao[:-1]
    with pytest.raises(SettingsError, match=r"damaged: its ao holds \d+ texels, not the \d+ covered"):
        back.check()


def test_bad_atlases_are_refused_by_name():
    floor, lid, _ = scene()
    with pytest.raises(SettingsError, match="list of targets is empty"):
        bake_ao([], [], **KW)
    twin = Mesh(lid.positions + 5, lid.triangles, uvs=lid.uvs, name="Floor")
    with pytest.raises(SettingsError, match=r"'Floor' names more than one"):
        bake_ao([floor, twin], [], **KW)
    with pytest.raises(SettingsError, match="occluding has 1 entries for 2 targets"):
        bake_ao(Atlas([floor, lid], occluding=[True]), [], **KW)
    with pytest.raises(SettingsError, match="an atlas over UDIM tiles is not denoised"):
        core.bake_udim([floor, lid], [], **dict(KW, denoise=True))


def test_ownership_of_coverages_directly():
    rank = A.name_rank(["b", "a", "c"])
    assert rank.tolist() == [1, 0, 2]
    t = np.array([0, 1, 2])
    own = A.owners([(t, np.array([0.5, 0.6, 1.0])), (t, np.array([0.5, 0.4, 0.2])), (np.array([3]), np.array([1.0]))],
                   rank, 4, 1)
    assert own.owner.tolist() == [[1, 0, 0, 2]]
    assert own.overlaps == [(1, 0, 1)] and own.shared == 3
    assert A.within_reach((np.zeros(3), np.ones(3)), (np.array([1.5, 0, 0]), np.array([2, 1, 1])), 0.5)
    assert not A.within_reach((np.zeros(3), np.ones(3)), (np.array([1.6, 0, 0]), np.array([2, 1, 1])), 0.5)


def test_the_id_map_colours_each_target_by_its_name():
    owner = np.array([[0, 1, -1], [1, 0, 2]], np.int32)
    m = A.id_map(owner, ("Body", "Eyes", "Hair"))
    assert m.shape == (2, 3, 3) and m.dtype == np.float32
    np.testing.assert_array_equal(m[0, 2], 0.0)
    for (r, c), name in (((0, 0), "Body"), ((0, 1), "Eyes"), ((1, 2), "Hair")):
        np.testing.assert_array_equal(m[r, c], A.id_colour(name))
    # an object keeps its colour whatever else the atlas holds
    np.testing.assert_array_equal(A.id_map(np.array([[0]], np.int32), ("Eyes",))[0, 0], A.id_colour("Eyes"))
    colours = np.array([A.id_colour(f"Part{k}") for k in range(20)])
    assert len({tuple(np.round(c, 3)) for c in colours}) == 20 and colours.max(axis=1).min() >= 0.75


def test_a_kept_target_within_reach_of_a_changed_one_is_said_to_be_stale():
    kw = dict(resolution=(160, 64), samples=4, seed=2, margin=2, threads=2, max_distance=0.7)
    first = bake_ao(ten_boxes(), [], **kw)
    moved = ten_boxes(moved=5)
    r = bake_ao(Atlas([moved[5]], keep=first.record), [], **kw)  # Box5 alone: the others are held
    warnings = r.report.get("warnings", [])
    assert any(w.startswith("Box4 was not baked now, and Box5 within its reach changed") for w in warnings)
    assert any(w.startswith("Box6 was not baked now") for w in warnings)
    assert not any(w.startswith(("Box3 ", "Box7 ")) for w in warnings)


def test_the_same_bits_on_a_dask_cluster():
    distributed = pytest.importorskip("distributed")
    import os

    root = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
    with distributed.LocalCluster(n_workers=2, threads_per_worker=1, processes=True, host="127.0.0.1",
                                  dashboard_address=None, silence_logs=40) as cluster, distributed.Client(cluster) as client:
        client.run(lambda: __import__("sys").path.insert(0, root))
        targets = scene()
        ref = bake_ao(targets, [], **KW)
        r = bake_ao(targets, [], **dict(KW, workers=client))
    for name in ("ao", "stderr", "samples", "mask", "owner"):
        np.testing.assert_array_equal(getattr(r, name), getattr(ref, name), err_msg=name)


def test_an_atlas_over_udim_tiles_is_each_tiles_atlas():
    """A floor over tiles 1001 and 1002 and a lid in 1001 only: tile 1002 holds the floor alone (the lid
    occluding it as a mesh), tile 1001 both; each target's texels are its own UDIM bake's."""
    floor = quad("Floor", -1, -1, 0.0, 2, (0.5, 0.0), (2.0, 1.0))
    lid = quad("Lid", -0.5, -0.5, 0.3, 1, (0.1, 0.1), (0.4, 0.9), down=True)
    r = core.bake_udim([floor, lid], [], **KW)
    assert sorted(r.tiles) == [1001, 1002] and r.owner.shape == (2, 64, 64) and r.targets == ("Floor", "Lid")
    assert set(np.unique(r.owner[1]).tolist()) == {0} and set(np.unique(r.owner[0]).tolist()) == {-1, 0, 1}
    alone = core.bake_udim(floor, [lid], **KW)
    for k in range(2):
        mine = r.mask[k] & (r.owner[k] == 0)
        np.testing.assert_array_equal(r.ao[k][mine], alone.ao[k][mine])
    again = core.bake_udim(Atlas([floor, lid], keep=r.record), [], **KW)
    assert again.report["atlas"]["baked"] == [] and np.array_equal(again.ao, r.ao)
