"""Occluder sets, ground, quantity and channel settings without Blender: the script's options, the
manifest's keys, the checks before any work, and that libraries baked before these settings still
count as done."""

import os
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parent.parent
if str(ROOT) not in sys.path:
    sys.path.insert(0, str(ROOT))

from mc_ao import cli, filewriter, schema  # noqa: E402
from mc_ao.settings import BakeSettings  # noqa: E402

NEW = ("occluder_collections", "exclude_collections", "only_local", "ground", "ground_height", "quantity", "channel",
       "into")


def parse(*args):
    namespace = cli.make_parser(with_blend=True).parse_args(["scene.blend", *args])
    cli.default_formats(namespace)
    return cli.settings_from(namespace)


def refused(*args):
    with pytest.raises(cli.UsageError) as info:
        parse(*args)
    return str(info.value)


def test_each_new_setting_is_in_the_schema_once_with_an_option_and_a_tooltip():
    names = [s.name for s in schema.SETTINGS]
    options = {s.name: s.option for s in schema.SETTINGS}
    for name in NEW:
        assert names.count(name) == 1, name
        assert schema.BY_NAME[name].help and schema.BY_NAME[name].label
    assert [options[n] for n in NEW] == ["--occluder-collections", "--exclude-collections", "--only-local", "--ground",
                                         "--ground-height", "--quantity", "--channel", "--into"]
    help_text = cli.make_parser(with_blend=True).format_help()
    for name in NEW:
        assert options[name] in help_text


def test_the_script_options_give_the_settings():
    assert parse() == BakeSettings(height=1024)  # --resolution N is N x N
    s = parse("--occluder-collections", "Props", "Rocks", "--exclude-collections", "Floor", "--only-local",
              "--quantity", "ao", "thickness")
    assert s.occluder_collections == ("Props", "Rocks") and s.exclude_collections == ("Floor",)
    assert s.only_local and s.quantity == ("AO", "THICKNESS") and s.quantities == ("ao", "thickness")
    assert parse("--quantity", "thickness").quantities == ("thickness",)
    assert parse("--quantity", "THICKNESS").quantities == ("thickness",)  # any case, as --channel R


def test_ground_flag_is_each_objects_lowest_point_and_a_height_is_a_fixed_plane():
    assert parse().ground_value() is None
    auto = parse("--ground")
    assert (auto.ground, auto.ground_value()) == ("AUTO", "auto")
    fixed = parse("--ground-height", "-0.25")
    assert (fixed.ground, fixed.ground_value()) == ("HEIGHT", -0.25)
    assert fixed.bake_kwargs()["ground"] == -0.25 and "ground" not in parse().bake_kwargs()
    assert "--ground and --ground-height both place the ground" in refused("--ground", "--ground-height", "1")
    assert "--ground-height must be a finite number" in refused("--ground-height", "nan")


def test_channel_takes_r_g_b_a_and_needs_an_image():
    s = parse("--channel", "R", "--into", "ORM")
    assert (s.channel, s.into) == ("R", "ORM")
    assert "--into must name the image" in refused("--channel", "g")
    assert "--into names 'ORM' but Channel is off" in refused("--into", "ORM")
    assert "--channel takes the AO alone" in refused("--channel", "r", "--into", "ORM", "--quantity", "thickness")
    assert "not with color attributes or UDIM" in refused("--channel", "a", "--into", "ORM", "--udim")


def test_contradictions_are_refused_before_any_work():
    message = refused("--occluder-collections", "Props", "Floor", "--exclude-collections", "Floor")
    assert "'Floor'" in message and "remove it from one list" in message
    assert "--bent-normals come from the AO's rays" in refused("--quantity", "thickness", "--bent-normals")
    assert "one quantity into a color attribute" in refused("--target", "vertex-colors", "--quantity", "ao",
                                                            "thickness")
    assert "one quantity with Selected to Active" in refused("--selected-to-active", "--quantity", "ao", "thickness")
    assert "--quantity must be one or more of AO, THICKNESS, each once" in refused("--quantity", "ao", "ao")


def test_the_occluders_choice_keeps_its_stored_value_under_its_new_name():
    setting = schema.BY_NAME["occluders"]
    assert dict((i, name) for i, name, _ in setting.items)["VISIBLE"] == "All Rendered"
    assert setting.identifiers == ("SELF", "SELECTED", "VISIBLE")  # the order Blender stores as a number
    assert parse("--occluders", "visible").occluders == "VISIBLE" == setting.default


def test_the_settings_record_adds_the_new_keys_only_when_set():
    plain = filewriter.settings_record(BakeSettings())
    assert not set(plain) & {*NEW, "quantity"}
    record = filewriter.settings_record(parse("--occluder-collections", "A", "B", "--exclude-collections", "C",
                                              "--only-local", "--ground-height", "0.5", "--quantity", "ao",
                                              "thickness"))
    assert {k: record[k] for k in record if k not in plain} == {
        "occluder_collections": "A, B", "exclude_collections": "C", "only_local": True, "ground": "height",
        "ground_height": 0.5, "quantity": "ao thickness"}


def test_image_names_of_each_quantity():
    s = BakeSettings(quantity=("AO", "THICKNESS"))
    assert [s.quantity_image_name_for("Rock", q) for q in s.quantities] == ["Rock_AO", "Rock_Thickness"]
    assert s.quantity_image_name_for("Rock", "thickness", suffix="_stderr") == "Rock_Thickness_stderr"
    long = "x" * 300
    names = {s.quantity_image_name_for(long, q, 63) for q in s.quantities}
    assert len(names) == 2 and all(len(n) <= 63 and n.endswith(("_AO", "_Thickness")) for n in names)


def plan(tmp_path, text):
    from mc_ao_batch.manifest import plan as plan_manifest

    blend = tmp_path / "asset.blend"
    blend.write_bytes(b"BLENDER-v402" + b"\0" * 100)
    os.utime(blend, ns=(1_700_000_000_000_000_000, 1_700_000_000_000_000_000))
    manifest = tmp_path / "m.toml"
    manifest.write_text(f"[[bake]]\nblend = 'asset.blend'\n{text}")
    (task,) = plan_manifest(manifest, tmp_path / "out")
    return task


def test_manifest_keys_are_the_options_names(tmp_path):
    task = plan(tmp_path, "occluder_collections = ['Props', 'Rocks']\nexclude_collections = 'Floor'\n"
                          "only_local = true\nground_height = -0.5\nquantity = ['ao', 'thickness']\n")
    s = parse(*task.args)
    assert (s.occluder_collections, s.exclude_collections, s.only_local) == (("Props", "Rocks"), ("Floor",), True)
    assert (s.ground, s.ground_height, s.quantities) == ("HEIGHT", -0.5, ("ao", "thickness"))
    s = parse(*plan(tmp_path, "ground = true\nquantity = 'thickness'\n").args)
    assert (s.ground, s.quantities) == ("AUTO", ("thickness",))
    s = parse(*plan(tmp_path, "channel = 'R'\ninto = 'Rock_ORM'\n").args)
    assert (s.channel, s.into) == ("R", "Rock_ORM")


def test_a_manifest_that_names_the_new_settings_at_their_defaults_keeps_its_fingerprint(tmp_path):
    # A library baked before these settings existed still counts as done (tests/test_settings_compat.py
    # holds the previous version's fingerprints); saying the defaults out loud changes nothing either.
    before = plan(tmp_path, "samples = 64\noccluders = 'visible'\n").fingerprint
    same = plan(tmp_path, "samples = 64\noccluders = 'visible'\nquantity = 'ao'\nonly_local = false\nground = false\n"
                          "channel = 'none'\n").fingerprint
    assert same == before
    for text in ("quantity = 'thickness'\n", "ground = true\n", "ground_height = 0.0\n", "only_local = true\n",
                 "occluder_collections = ['A']\n", "exclude_collections = ['A']\n"):
        assert plan(tmp_path, "samples = 64\noccluders = 'visible'\n" + text).fingerprint != before, text
