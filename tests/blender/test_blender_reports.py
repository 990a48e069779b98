"""What the user reads: warnings as sentences, the summary last, the panel's lines whole.

The status bar shows only the last report, so each object's warnings come before its summary, which
comes last and counts them; the panel keeps the last bake's outcome under the button. Notes about
the input are sentences, the same in the operator and in scripts/bake_ao.py. Labels in the panel
wrap at the sidebar's width instead of being cut off.
"""

import re
import types

import numpy as np
import pytest

from blender_helpers import add_cube, add_plane, new_session, select_only, tick_until

pytestmark = pytest.mark.blender


# -- notes about the input ------------------------------------------------------------------------

@pytest.mark.parametrize("key, count, sentence", [
    ("overlapping_texels", 163, "163 texels lie under overlapping UV islands; each averages every surface over it"),
    ("overlapping_texels", 1, "1 texel lies under overlapping UV islands; it averages every surface over it"),
    ("uv_outside_triangles", 12,
     "12 triangles reach outside the UV square [0, 1]; the parts outside are not baked"),
    ("uv_outside_triangles", 1, "1 triangle reaches outside the UV square [0, 1]; the part outside is not baked"),
    ("degenerate_uv_triangles", 3, "3 triangles have no area in the UV map and were skipped"),
    ("degenerate_uv_triangles", 1, "1 triangle has no area in the UV map and was skipped"),
    ("degenerate_triangles", 2, "2 triangles have no area in space and were skipped"),
    ("degenerate_triangles", 1, "1 triangle has no area in space and was skipped"),
])
def test_input_notes_are_sentences(addon, key, count, sentence):
    from mc_ao import summaries

    report = {"covered_texels": 500, "overlapping_texels": 0, "uv_outside_triangles": 0,
              "degenerate_uv_triangles": 0, "degenerate_triangles": 0}
    report[key] = count
    assert summaries.input_notes(types.SimpleNamespace(report=report)) == [sentence]


def test_each_note_is_about_a_count_the_core_reports(addon):
    """The notes are keyed by core.BakeResult.report's keys: a key renamed in the core must fail here."""
    import core
    from mc_ao import summaries

    plane = core.Mesh(
        positions=np.array([[0, 0, 0], [1, 0, 0], [1, 1, 0], [0, 1, 0]], float),
        triangles=np.array([[0, 1, 2], [0, 2, 3]]),
        uvs=np.array([[[0, 0], [1, 0], [1, 1]], [[0, 0], [1, 1], [0, 1]]], float),
    )
    result = core.bake_ao(plane, resolution=(8, 8), samples=4, threads=1)
    assert set(summaries._INPUT_NOTES) <= set(result.report)
    assert summaries.input_notes(result) == []  # a clean plane: nothing to say


# -- the order of the reports ---------------------------------------------------------------------

def overlapping(bpy, name, location):
    """A plane with a copy of itself on the same UVs: every texel is under two surfaces."""
    obj = add_plane(bpy, name, size=2, location=location)
    array = obj.modifiers.new("Copy", "ARRAY")
    array.relative_offset_displace = (1.5, 0.0, 0.0)
    return obj


def test_each_objects_warnings_come_before_its_summary_and_the_total_comes_last(bpy, scene):
    from mc_ao import operators

    a = overlapping(bpy, "A", (0, 0, 0))
    b = add_plane(bpy, "B", size=2, location=(0, 5, 0))
    lamp_data = bpy.data.lights.new("Lamp", "POINT")
    lamp = bpy.data.objects.new("Lamp", lamp_data)
    bpy.context.collection.objects.link(lamp)
    select_only(bpy, a, b, lamp)
    session, reports = new_session()
    assert session.start(bpy.context, live=False)
    assert tick_until(bpy, session, lambda: False) == {"FINISHED"}

    kinds = [kind for kind, _ in reports]
    texts = [text for _, text in reports]
    assert texts[0] == "Lamp: skipped, it is a light, not a mesh"
    assert texts[1] == "A: 576 texels lie under overlapping UV islands; each averages every surface over it"
    # A's summary counts the two warnings before it; B's has none; the whole bake's comes last.
    number = r"[0-9]+\.[0-9]{2}"
    # where the tiles ran (Processes and Threads automatic: the core chose, and says both predictions)
    where = r"(on [0-9]+ threads?|in [0-9]+ worker processes)"
    ran = rf" {where}( \(about {number} s against {number} s {where}\))?"
    assert kinds[2] == "WARNING" and re.fullmatch(
        rf"A: 24x24 into 'A_AO' in {number} s{ran}, 16 samples per texel, {number} M rays/s; "
        "occluded by itself and 1 other object; 2 warnings before this, in the Info editor", texts[2])
    assert kinds[3] == "INFO" and re.fullmatch(
        rf"B: 24x24 into 'B_AO' in {number} s{ran}, 16 samples per texel, {number} M rays/s; "
        "occluded by itself and 1 other object", texts[3])
    assert kinds[4] == "WARNING" and re.fullmatch(
        rf"AO bake: 2 objects in {number} s, 16 samples per texel, {number} M rays/s; "
        "2 warnings before this, in the Info editor", texts[4])
    assert len(reports) == 5
    assert operators.last_outcome == reports[-1]  # what the panel shows


def test_a_clean_bake_ends_with_its_summary_as_info(bpy, scene):
    from mc_ao import operators

    ground = add_plane(bpy, "Ground", size=4)
    add_cube(bpy, "Block", size=1.0, location=(0, 0, 0.8))
    select_only(bpy, ground)
    session, reports = new_session()
    assert session.start(bpy.context, live=True)
    assert tick_until(bpy, session, lambda: False) == {"FINISHED"}
    kind, text = reports[-1]
    assert kind == "INFO" and text.startswith("Ground: 24x24 into 'Ground_AO' in ") and "warning" not in text
    assert text.endswith(" M rays/s; occluded by itself and 1 other object")
    assert operators.last_outcome == reports[-1]


def test_the_summary_says_where_the_tiles_ran_and_why(bpy, scene):
    """Processes 0 and Threads 0: the core weighs Blender's threads against worker processes (by its
    model's prediction of each) and the summary says which ran and both predictions; given counts are
    said as they ran."""
    from mc_ao import corelink

    ground = add_plane(bpy, "Ground", size=4)
    add_cube(bpy, "Block", size=1.0, location=(0, 0, 0.8))
    select_only(bpy, ground)
    s = scene.mc_ao
    s.threads, s.processes = 0, 0
    session, reports = new_session()
    assert session.start(bpy.context, live=False)
    assert tick_until(bpy, session, lambda: False) == {"FINISHED"}
    (_, text), = reports
    cores = corelink.load("base.machine").cpu_count()
    m = re.search(r" in [0-9.]+ s (on|in) ([0-9]+) (threads?|worker processes) \(about ([0-9.]+) s against "
                  r"([0-9.]+) s (on|in) ([0-9]+) (threads?|worker processes)\), 16 samples per texel", text)
    if cores == 1:  # one core: nothing to weigh
        assert m is None and " on 1 thread, " in text
        return
    assert m, text
    chosen, other = float(m.group(4)), float(m.group(5))
    assert chosen <= other  # the sooner of the two ran
    assert {m.group(3), m.group(8)} == {"threads" if cores > 1 else "thread", "worker processes"}
    s.processes = 1  # given: as it ran, no weighing
    session, reports = new_session()
    assert session.start(bpy.context, live=False)
    assert tick_until(bpy, session, lambda: False) == {"FINISHED"}
    assert f" s on {cores} threads, 16 samples per texel" in reports[-1][1] and "against" not in reports[-1][1]


# -- the panel ------------------------------------------------------------------------------------

@pytest.fixture(autouse=True)
def idle_machine(monkeypatch):
    """The estimates here as the bare model gives them: an idle machine (the load average changes
    between two reads on a shared one), the worker pool running (no start priced), no calibration by
    earlier bakes; tests/blender/test_blender_panel.py and tests/test_estimate.py price those."""
    from mc_ao import baking, corelink

    monkeypatch.setattr(corelink.load("execution.cost"), "machine_load", lambda: (None, None))
    monkeypatch.setattr(corelink.load("execution.executor"), "pool_ready", lambda *_: True)
    monkeypatch.setitem(baking._CALIBRATION, "factor", 1.0)


class FakeLayout:
    """Records a panel's labels and their icons (a panel cannot be drawn without a window)."""

    def __init__(self):
        self.labels = []

    def row(self, **_):
        return self

    column = row

    def operator(self, *_, **__):
        return None

    def label(self, text="", icon="NONE"):
        self.labels.append((text, icon))


class SidebarContext:
    """bpy.context as a panel in a sidebar of ``width`` pixels sees it (bpy has no window here)."""

    def __init__(self, bpy, width):
        self._context = bpy.context
        self.region = types.SimpleNamespace(width=width)

    def __getattr__(self, name):
        return getattr(self._context, name)


def draw_main_panel(bpy, width, last_outcome=None):
    from mc_ao import operators, panel

    layout = FakeLayout()
    kept, operators.last_outcome = operators.last_outcome, last_outcome
    try:
        panel.VIEW3D_PT_mc_ao.draw(types.SimpleNamespace(layout=layout), SidebarContext(bpy, width))
    finally:
        operators.last_outcome = kept
    return layout.labels


# Blender's default sidebar: about 280 pixels wide at UI scale 1, its tabs included (4.3: 291 at 1.04).
SIDEBAR = 280


@pytest.mark.parametrize("name", ["Flat", "Suzanne without UVs", "A_very_long_object_name_from_an_importer_001"])
def test_the_no_uv_reason_fills_its_rows_at_the_sidebars_width(bpy, scene, name):
    """The reason takes the rows of the panel's first line whatever it says, each row within the
    sidebar's width; what does not fit ends in an ellipsis (the button's tooltip has it whole)."""
    from mc_ao import baking, panel

    flat = add_plane(bpy, name, size=2)
    flat.data.uv_layers.remove(flat.data.uv_layers[0])
    select_only(bpy, flat)
    reason = baking.why_not_bakeable([flat])
    labels = draw_main_panel(bpy, SIDEBAR)

    rows = labels[:panel.WHAT_LINES]
    shown = " ".join(text for text, _ in rows if text)
    assert shown == reason or (shown.endswith("\u2026") and reason.startswith(shown[:-1].rstrip("\u2026 ")[:20]))
    assert rows[0][1] == "INFO" and all(icon == "BLANK1" for text, icon in rows[1:] if text)
    room = SIDEBAR - panel.LABEL_INSET
    for text, _ in labels:
        assert panel.text_width(text, bpy.context) <= room, text
    assert len(labels) == ROWS  # the same rows as a bake that can go


#: Rows of the main panel under its two buttons, whatever they say.
ROWS = 7


def test_the_panel_shows_the_last_bakes_outcome(bpy, scene):
    from mc_ao import panel

    ground = add_plane(bpy, "Ground", size=4)
    select_only(bpy, ground)
    outcome = ("WARNING", "Ground: 24x24 into 'Ground_AO' in 0.05 s, 16 samples per texel, 1.00 M rays/s; "
                          "1 warning before this, in the Info editor")
    labels = draw_main_panel(bpy, SIDEBAR, last_outcome=outcome)
    assert ROWS == panel.WHAT_LINES + panel.ESTIMATE_LINES + panel.NOTE_LINES + panel.LAST_LINES
    assert len(labels) == ROWS
    assert labels[0] == ("Into Ground_AO", "IMAGE_DATA")
    last = labels[ROWS - panel.LAST_LINES:]
    assert last[0][0].startswith("Last bake: Ground: 24x24") and last[0][1] == "ERROR"  # the warning icon
    shown = " ".join(text for text, _ in last)
    assert shown.endswith("\u2026") and ("Last bake: " + outcome[1]).startswith(shown[:-2])
    before = draw_main_panel(bpy, SIDEBAR)
    assert len(before) == ROWS and not any(text.startswith("Last bake") for text, _ in before)  # before any bake


def test_fitted_lines_cut_at_spaces_into_a_fixed_number_of_rows(addon):
    from mc_ao import panel

    assert panel.fitted_lines("aa bb cc dd", 5, len, 2) == ["aa bb", "cc dd"]
    assert panel.fitted_lines("aa bb", 5, len, 3) == ["aa bb", "", ""]
    assert panel.fitted_lines("aa bb cc dd ee", 5, len, 2) == ["aa bb", "cc \u2026"]
    assert panel.fitted_lines("aa bbbbbbbb cc", 5, len, 3) == ["aa", "bbbb\u2026", "cc"]  # a word longer than a row
    assert panel.fitted_lines("aabbccddee ff", 5, len, 1) == ["aabb\u2026"]
    assert panel.fitted_lines("", 5, len, 2) == ["", ""]
    for text in ("aa bb cc dd ee ff", "aabbccddeeff gg", "a b c d e f g h i j"):
        for rows in (1, 2, 3):
            lines = panel.fitted_lines(text, 5, len, rows)
            assert len(lines) == rows and all(len(line) <= 5 for line in lines), (text, rows, lines)


def test_the_last_bake_line_belongs_to_the_file_and_the_last_action(bpy, scene, tmp_path):
    """After a bake, opening another file forgets its line; a refused bake replaces a success."""
    from mc_ao import operators

    ground = add_plane(bpy, "Ground", size=2)
    select_only(bpy, ground)
    scene.mc_ao.resolution, scene.mc_ao.samples = 8, 2
    assert bpy.ops.object.mc_ao_bake() == {"FINISHED"}
    assert operators.last_outcome[0] == "INFO"
    # A refused bake (settings that cannot go together, found when it starts) is the last action now.
    scene.mc_ao.target, scene.mc_ao.quantity = "VERTEX_COLORS", {"AO", "THICKNESS"}
    with pytest.raises(RuntimeError):
        bpy.ops.object.mc_ao_bake()
    assert operators.last_outcome is not None and operators.last_outcome[0] == "ERROR"
    assert "one quantity" in operators.last_outcome[1]
    scene.mc_ao.target, scene.mc_ao.quantity = "IMAGE_TEXTURES", {"AO"}
    assert bpy.ops.object.mc_ao_bake() == {"FINISHED"} and operators.last_outcome[0] == "INFO"
    # Another file: nothing of this one's bake is shown there.
    other = tmp_path / "other.blend"
    bpy.ops.wm.save_as_mainfile(filepath=str(other), copy=True)
    bpy.ops.wm.open_mainfile(filepath=str(other))
    assert operators.last_outcome is None


def test_the_panel_shows_what_the_bake_will_cost_and_warns_before_it_does_not_fit(bpy, scene, monkeypatch):
    from mc_ao import baking, corelink
    from mc_ao.settings import BakeSettings

    ground = add_plane(bpy, "Ground", size=4)
    select_only(bpy, ground)
    scene.mc_ao.resolution, scene.mc_ao.samples = 1024, 128
    labels = draw_main_panel(bpy, SIDEBAR)
    estimate = shown_estimate(bpy)
    assert estimate.startswith("Estimate: about ") and ("MiB" in estimate or "GiB" in estimate)
    cost = baking.bake_cost(BakeSettings.from_properties(scene.mc_ao), [ground])
    # A 1024^2 plane (all of it covered) at 128 samples, alone in the scene, on the workers Processes 0
    # picks for its 2 triangles: what core.execution.cost says, the panel shows.
    processes, threads = bake_processes(scene, (2, 0, 0))
    assert cost == corelink.load("execution.cost").estimate(1024 * 1024, 128, 2, image_texels=1024 * 1024,
                                                   threads=threads, processes=processes)
    assert estimate == f"Estimate: {cost.describe()}"
    assert not any(icon == "ERROR" for _, icon in labels)
    monkeypatch.setattr(corelink.load("execution.executor"), "memory_limit", lambda: 1 << 20)  # 1 MiB free
    labels = draw_main_panel(bpy, SIDEBAR)
    warned = [text for text, icon in labels if icon == "ERROR"]
    assert warned and warned[0].startswith("Estimate: ") and len(labels) == ROWS
    assert "GiB free" in " ".join(text for text, _ in labels)


def collection_of(bpy, name, *objects):
    """A new collection in the scene holding ``objects`` (moved out of their own)."""
    collection = bpy.data.collections.new(name)
    bpy.context.scene.collection.children.link(collection)
    for obj in objects:
        for c in list(obj.users_collection):
            c.objects.unlink(obj)
        collection.objects.link(obj)
    return collection


def grid(bpy, name, cuts, location):
    """A subdivided plane of 2 (cuts + 1)^2 triangles."""
    obj = add_plane(bpy, name, size=2, location=location)
    obj.modifiers.new("Cuts", "SUBSURF").subdivision_type = "SIMPLE"
    obj.modifiers["Cuts"].levels = obj.modifiers["Cuts"].render_levels = 0
    bpy.ops.object.select_all(action="DESELECT")
    obj.select_set(True)
    bpy.context.view_layer.objects.active = obj
    bpy.ops.object.mode_set(mode="EDIT")
    bpy.ops.mesh.subdivide(number_cuts=cuts)
    bpy.ops.object.mode_set(mode="OBJECT")
    obj.modifiers.remove(obj.modifiers["Cuts"])
    return obj


def shown_estimate(bpy):
    """The panel's estimate line, its rows joined."""
    from mc_ao import panel

    labels = draw_main_panel(bpy, SIDEBAR)
    start = [icon for _, icon in labels].index("TIME")
    return " ".join(text for text, _ in labels[start:start + panel.ESTIMATE_LINES] if text)


def occluder_triangles(job):
    return sum(len(arrays.triangles) for arrays in job.occluders)


def test_the_estimate_prices_the_occluders_the_bake_will_use_apart(bpy, scene):
    """The estimate counts the target's triangles and those of the occluders plan() gives it (Include and
    Exclude, instances, Occludes Other Objects) apart, as core.execution.cost prices them: excluding a heavy
    occluder collection lowers its memory by core.execution.cost's bytes for those triangles, in each process."""
    from mc_ao import baking, corelink
    from mc_ao.settings import BakeSettings

    cost = corelink.load("execution.cost")
    for collection in list(bpy.data.collections):
        bpy.data.collections.remove(collection)
    floor = add_plane(bpy, "Floor", size=4)
    heavy = grid(bpy, "Heavy", 99, (0, 0, 3))  # 2 x 100^2 triangles
    box = add_cube(bpy, "Box", size=0.5, location=(0, 0, 1))
    loner = add_cube(bpy, "Loner", size=0.5, location=(1, 1, 1))
    loner.mc_ao.occlude_others = False  # occludes only itself: not the floor's occluder
    collection_of(bpy, "Heavy", heavy)
    boxes = collection_of(bpy, "Boxes", box)
    placed = bpy.data.objects.new("Placed", None)  # Boxes again, as a collection instance
    placed.instance_type, placed.instance_collection = "COLLECTION", boxes
    placed.location = (-1, -1, 0)
    bpy.context.scene.collection.objects.link(placed)
    bpy.context.view_layer.update()
    select_only(bpy, floor)
    s = scene.mc_ao
    s.resolution, s.samples, s.processes, s.threads = 256, 64, 2, 0
    heavy_triangles = 2 * 100 ** 2
    assert len(heavy.data.loops) - 2 * len(heavy.data.polygons) == heavy_triangles

    def estimate_and_plan():
        settings = BakeSettings.from_properties(s)
        depsgraph = bpy.context.evaluated_depsgraph_get()
        (job,) = baking.plan(depsgraph, [floor], settings, selected=[floor], view_layer=bpy.context.view_layer)
        return baking.bake_cost(settings, [floor], depsgraph, selected=[floor]), occluder_triangles(job)

    def expected(occluders):
        processes, threads = bake_processes(scene, (2, occluders, 0))
        return cost.estimate(256 * 256 * baking.uv_coverage(floor), 64, 2, image_texels=256 * 256, threads=threads,
                             processes=processes, occluder_triangles=occluders)

    every, occluders = estimate_and_plan()
    assert occluders == heavy_triangles + 2 * 12  # the grid, the box and its instance; not the loner
    assert every == expected(occluders)
    assert shown_estimate(bpy) == f"Estimate: {every.describe()}"

    s.exclude_collections.add().collection = bpy.data.collections["Heavy"]
    fewer, occluders = estimate_and_plan()
    assert occluders == 2 * 12
    assert fewer == expected(occluders)
    # 2 processes each hold the grid's occluder scenes, the parent its share while they bake.
    assert every.bytes - fewer.bytes == heavy_triangles * (2 * cost.BYTES_PER_OCCLUDER_TRIANGLE
                                                           + cost.BYTES_PER_PARENT_OTHER_TRIANGLE)
    assert shown_estimate(bpy) == f"Estimate: {fewer.describe()}"
    # The grid back in, disabled in renders instead: the panel counts again (the counts are kept only
    # until the data changes).
    s.exclude_collections.clear()
    assert shown_estimate(bpy) == f"Estimate: {every.describe()}"
    heavy.hide_render = True
    assert shown_estimate(bpy) == f"Estimate: {fewer.describe()}"
    assert estimate_and_plan() == (fewer, 2 * 12)

    # Processes 0: as many as the bake picks for these counts (core.execution.executor.auto_workers).
    s.processes = 0
    auto, occluders = estimate_and_plan()
    assert auto == expected(occluders)
    s.only_local = True  # the floor alone: no occluders
    alone, occluders = estimate_and_plan()
    assert occluders == 0 and alone == expected(0)


def test_the_estimate_of_selected_to_active_prices_the_high_poly_apart(bpy, scene):
    from mc_ao import baking, corelink, selected_to_active
    from mc_ao.settings import BakeSettings

    cost = corelink.load("execution.cost")
    low = add_plane(bpy, "Low", size=2)
    high = grid(bpy, "High", 49, (0, 0, 0.01))  # 2 x 50^2 triangles
    box = add_cube(bpy, "Box", size=0.5, location=(0, 0, 1))  # renders: an occluder of All Rendered
    select_only(bpy, low, high)
    s = scene.mc_ao
    s.use_selected_to_active, s.resolution, s.samples, s.processes, s.threads = True, 128, 16, 2, 0
    settings = BakeSettings.from_properties(s)
    depsgraph = bpy.context.evaluated_depsgraph_get()
    job = selected_to_active.plan(depsgraph, low, [low, high], settings, view_layer=bpy.context.view_layer)
    highpoly = sum(len(arrays.triangles) for arrays in job.highpoly)
    assert highpoly == 2 * 50 ** 2 and occluder_triangles(job) == 12
    estimate = baking.bake_cost(settings, [low], depsgraph, highpoly=[high])
    processes, threads = bake_processes(scene, (2, 12, highpoly))
    assert estimate == cost.estimate(128 * 128 * baking.uv_coverage(low), 16, 2, image_texels=128 * 128,
                                     threads=threads, processes=processes, occluder_triangles=12,
                                     highpoly_triangles=highpoly)
    assert shown_estimate(bpy) == f"Estimate: {estimate.describe()}"


def bake_processes(scene, triangles):
    """(processes, threads each) that core.bake_ao takes for the scene's Processes and Threads and a
    bake of ``triangles`` (target, occluders, high-poly)."""
    from mc_ao import corelink

    workers = corelink.load("execution.executor")
    threads = scene.mc_ao.threads or None
    return workers.processes_of("auto" if scene.mc_ao.processes == 0 else scene.mc_ao.processes, threads,
                                types.SimpleNamespace(threads=threads or workers.cpu_count()), triangles)


def test_no_setting_label_is_cut_off_at_the_sidebars_default_width(bpy, scene):
    """Every label left of a field, and every menu's value, measures no more than the longest that the
    real Blender 4.3 showed whole at the sidebar's default width ("Noise Threshold" as a label, "Color
    Attributes" in a menu); "Max Ray Distance" as a label and "Image Textures" in half a row were cut."""
    from mc_ao import panel

    drawn = []

    class Recorder:
        def __init__(self, split=False):
            object.__setattr__(self, "is_split", split)  # labels left of the fields, a checkbox's name in the right half

        def __getattr__(self, name):
            if name == "prop":
                return lambda data, prop, **kw: drawn.append((data, prop, kw, self.is_split))
            return lambda *a, **k: self

        def __setattr__(self, name, value):
            pass

    settings = scene.mc_ao
    from blender_helpers import add_plane, select_only

    select_only(bpy, add_plane(bpy, "Ground"))  # the Object sub-panel draws the active object's settings
    for target in ("IMAGE_TEXTURES", "VERTEX_COLORS"):
        settings.target = target
        for use_cage in (False, True):
            settings.use_cage = use_cage
            for cls in (getattr(panel, n) for n in dir(panel) if n.startswith("VIEW3D_PT_mc_ao")):
                panel_self = types.SimpleNamespace(layout=Recorder(), split_layout=lambda: Recorder(split=True))
                cls.draw(panel_self, bpy.context)
    label_room = panel.text_width("Noise Threshold", bpy.context)
    value_room = panel.text_width("Color Attributes", bpy.context)
    check_room = panel.text_width("Link Image to File", bpy.context)
    for data, prop, kw, split in drawn:
        rna = data.bl_rna.properties[prop]
        if rna.type == "BOOLEAN" and kw.get("text") != "":
            # a checkbox's name has the whole row, or in a split layout the right half: there the real
            # Blender 4.3 showed "Link Image to File" whole and cut "Occludes Other Objects" off
            if split:
                assert panel.text_width(kw.get("text", rna.name), bpy.context) <= check_room, rna.name
            continue
        if kw.get("text") == "":
            continue
        label = kw.get("text", rna.name)
        assert panel.text_width(label, bpy.context) <= label_room, label
        assert not kw.get("expand"), prop  # a row of buttons cuts every name in it
        if rna.type == "ENUM":
            for item in rna.enum_items:
                assert panel.text_width(item.name, bpy.context) <= value_room, item.name
