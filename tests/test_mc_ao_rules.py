"""The rules between settings live in mc_ao.rules, once: each breaks on what it says, reads in the
panel's words and in the script's, and the batch's manifest keys come from mc_ao.schema (no bpy)."""

import dataclasses
from types import SimpleNamespace

import pytest

from mc_ao import rules, schema
from mc_ao.settings import BakeSettings

# The script's own options at their defaults, as mc_ao.settings.from_options hands them to the rules.
OPTIONS = {o.key: None for o in schema.OPTIONS}
OPTIONS.update(format=["png"], attribute_type="float", resolution=(1024, 1024), overwrite_input=False, quiet=False)

# One combination that breaks each rule (in RULES' order), and a word its message has in each front end.
BREAKS = [
    (dict(target="VERTEX_COLORS", attribute_name=" ", format=["ply"]), "color attribute", "color attribute"),
    (dict(use_selected_to_active=True, target="VERTEX_COLORS", format=["ply"]), "set Target to Image Textures",
     "set --target to image-textures"),
    (dict(use_selected_to_active=True, use_udim=True), "turn off UDIM Tiles", "turn off --udim"),
    (dict(use_selected_to_active=True, bent_normals=True), "turn off Bent Normals", "turn off --bent-normals"),
    (dict(occluder_collections=("A", "B"), exclude_collections=("B",)), "names 'B'", "names 'B'"),
    (dict(quantity=("THICKNESS",), bent_normals=True), "AO's rays", "AO's rays"),
    (dict(quantity=("AO", "THICKNESS"), target="VERTEX_COLORS", format=["ply"]), "choose AO", "choose AO"),
    (dict(quantity=("AO", "THICKNESS"), use_selected_to_active=True), "Selected to Active", "Selected to Active"),
    (dict(channel="R"), "receives the AO", "receives the AO"),
    (dict(channel="R", into="ORM", use_udim=True), "UDIM tiles", "UDIM tiles"),
    (dict(channel="R", into="ORM", quantity=("THICKNESS",)), "AO alone", "AO alone"),
    (dict(into="ORM"), "names 'ORM' but Channel is off", "names 'ORM' but Channel is off"),
    (dict(denoise=True, samples=1), "at least 2 with Denoise: ", "at least 2 with --denoise: "),
    (dict(target="VERTEX_COLORS", error_map=True, format=["ply"]), "standard error", "standard error"),
    (dict(images="ATLAS", target="VERTEX_COLORS", format=["ply"]), "set Target to Image Textures",
     "set --target to image-textures"),
    (dict(images="ATLAS", use_udim=True), "turn off UDIM Tiles", "turn off --udim"),
    (dict(images="ATLAS", atlas=" "), "must name the image every object bakes into",
     "must name the image every object bakes into"),
    (dict(images="ATLAS", atlas="{object}_AO"), "leave out {object}", "leave out {object}"),
    (dict(id_map=True), "shows which object owns each texel", "shows which object owns each texel"),
    (dict(active="Low"), None, "is a setting of --selected-to-active (or --match-suffix), which is off"),
    (dict(cage=""), None, "is a setting of --selected-to-active"),
    (dict(cage_extrusion=0.1), None, "is a setting of --selected-to-active"),
    (dict(max_ray_distance=0.1), None, "is a setting of --selected-to-active"),
    (dict(use_selected_to_active=True, match_suffix=["_x", "_x"]), None, "not '_x' and '_x'"),
    (dict(use_selected_to_active=True, match_collections=True, match_suffix=["_h", "_l"]), None,
     "--match-suffix pairs them by name: give one"),
    (dict(match_collections=True), None, "needs --objects"),
    (dict(match_collections=True, active="A"), None, "with --match-collections, --objects names the low-poly objects"),
    (dict(use_selected_to_active=True, match_suffix=["_h", "_l"], active="A"), None,
     "with --match-suffix, --objects names the low-poly objects"),
    (dict(use_selected_to_active=True, match_suffix=["_h", "_l"], cage="C"), None, "NAME names one cage"),
    (dict(use_selected_to_active=True, cage="C", active="C"), None, "'C' is also the low-poly"),
    (dict(use_selected_to_active=True, active="A", objects=["A"]), None, "'A' is also among --objects"),
    (dict(target="VERTEX_COLORS", format=["png", "ply"]), None, "png: --target vertex-colors writes .ply files"),
    (dict(target="VERTEX_COLORS", format=["ply"], use_udim=True), None, "bakes images; --target vertex-colors"),
    (dict(target="VERTEX_COLORS", format=["ply"], bent_normals=True), None, "bakes images"),
    (dict(format=["ply"]), None, "ply is for --target vertex-colors"),
    (dict(save="x.blend"), None, "it needs --target vertex-colors"),
    (dict(target="VERTEX_COLORS", format=["ply"], save="x.txt"), None, "'x.txt' must name a .blend file"),
    (dict(bits="8", format=["exr"]), None, "8 cannot be written as exr: exr files take --bits half or float"),
    (dict(image_name="../{object}"), None, "'../{object}' is a path: give a name; files go into --output"),
    (dict(images="ATLAS", atlas="a/b"), None, "'a/b' is a path: give a name; files go into --output"),
]


def values(**changes):
    settings = {f.name: changes.pop(f.name) for f in dataclasses.fields(BakeSettings) if f.name in changes}
    return SimpleNamespace(**{**OPTIONS, **changes, **dataclasses.asdict(BakeSettings(**settings))})


def test_every_rule_has_a_breaking_example():
    assert len(BREAKS) == len(rules.RULES)
    assert not rules.broken(values(), schema.option_of, script=True)  # the defaults break none


@pytest.mark.parametrize("k", range(len(BREAKS)))
def test_each_rule_breaks_and_reads_in_both_front_ends(k):
    changes, panel_words, script_words = BREAKS[k]
    rule = rules.RULES[k]
    v = values(**changes)
    assert rule.broken(v), (rule.field, rule.message)
    got = rules.broken(v, schema.option_of, script=True)
    mine = [m for f, m in got if f == rule.field]
    said = [f"{schema.option_of(rule.field)} {m}" for m in mine]
    assert any(script_words in s for s in said), said
    assert not any("{" in m and "{object}" not in m for m in mine), mine  # every placeholder filled
    if rule.script:
        assert not [f for f, _ in rules.broken(v, schema.label_of) if f == rule.field and rule.script]
        return
    panel = [f"{schema.label_of(f)} {m}" for f, m in rules.broken(v, schema.label_of) if f == rule.field]
    assert any(panel_words in s for s in panel), panel
    assert not any("--" in s for s in panel), panel  # the panel's words, never an option


def test_the_operator_and_the_script_say_one_rule_in_their_own_words():
    settings = BakeSettings(use_selected_to_active=True, use_udim=True)
    assert schema.problems(settings) == [
        ("use_selected_to_active", "bakes AO into one image texture of the low-poly: turn off UDIM Tiles")]
    # The button's poll says it, whole, before any selection's reason.
    (field, message), = rules.broken(settings, schema.label_of, poll=True)
    assert f"{schema.label_of(field)} {message}" == (
        "Selected to Active bakes AO into one image texture of the low-poly: turn off UDIM Tiles")


def test_the_manifest_keys_are_the_schemas_and_match_the_scripts_parser():
    from mc_ao import cli

    actions = {a.dest: a for a in cli.make_parser(with_blend=True)._actions if a.option_strings}
    keys = schema.manifest_keys()
    for key, (option, shape) in keys.items():
        action = actions[key]
        assert option in action.option_strings
        want = {"flag": 0, "switch": 0, "list": "+", "pair": 2, "value?": "?", "value": None}[shape]
        assert (0 if action.nargs == 0 else action.nargs) == want, key
        # a switch (a setting on by default) is turned off by its --no- option, a flag has none
        assert ("--no-" + option[2:] in action.option_strings) == (shape == "switch"), key
    batch_set = {"output", "summary_json", "quiet", "help"}
    assert set(actions) - set(keys) == batch_set | {"save", "overwrite_input"}


@pytest.mark.parametrize("k", range(len(BREAKS)))
def test_each_rule_needs_every_part_of_its_example(k):
    """A rule that broke on less than it says (a condition dropped) is caught: going back to the default
    in any one setting of the example keeps it (but the settings there only to keep other rules quiet:
    the formats, Into beside a Channel, Selected to Active beside --match-suffix, which implies it)."""
    changes = BREAKS[k][0]
    rule = rules.RULES[k]
    context = {"format", "into"} | ({"use_selected_to_active"} if "match_suffix" in changes else set())
    for key in changes:
        if key in context and not (key == "into" and "channel" not in changes):
            continue
        rest = {name: value for name, value in changes.items() if name != key}
        assert not rule.broken(values(**rest)), (rule.field, rule.message, key)
