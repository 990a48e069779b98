"""mc_ao's settings map onto the core's bake options (core.base.request.OPTIONS), read when the add-on
loads and never repeated: each core option is given by a setting, set by the add-on itself (with a
reason), or a setting by itself; limits and choices are the core's (no bpy, no numpy)."""

import subprocess
import sys

from core.base import request
from mc_ao import schema
from mc_ao.settings import BakeSettings


def test_every_core_option_is_mapped_decided_or_a_setting_of_its_own():
    mapped = {s.core for s in schema.SETTINGS if s.core}
    for option in request.OPTIONS:
        assert (option.name in mapped) != (option.name in schema.CORE_INTERNAL), option.name
    assert set(schema.CORE_INTERNAL) <= set(request.BY_NAME)  # no reason kept for an option that is gone
    assert {s.core for s in schema.FROM_CORE} <= mapped


def test_the_limits_and_choices_are_the_cores():
    by = schema.BY_NAME
    assert (by["samples"].lo, by["samples"].hi) == (request.BY_NAME["samples"].lo, request.MAX_SAMPLES)
    assert (by["seed"].lo, by["seed"].hi) == (0, request.MAX_SEED)
    assert by["min_samples"].lo == request.BY_NAME["min_samples"].lo
    assert by["margin"].lo == request.BY_NAME["margin"].lo
    assert by["target_error"].lo == request.BY_NAME["target_error"].lo
    assert by["resolution"].hi == by["height"].hi == by["margin"].hi == request.MAX_RESOLUTION
    assert by["threads"].hi == by["processes"].hi == schema.MAX_THREADS == request.MAX_THREADS
    for name in ("source", "distribution", "quantity"):
        assert {i.lower() for i in by[name].identifiers} <= set(request.BY_NAME[name].choices), name


def test_a_bake_of_the_defaults_makes_a_request_the_core_takes():
    kw = BakeSettings().bake_kwargs(threads=2)
    made = request.BakeRequest.from_options("bake", "image", kw)
    assert made.samples == BakeSettings().samples and made.workers == "auto"


def test_a_core_option_alone_becomes_a_setting():
    option = request.Option("dummy_level", "choice", "low", "sampling", "a test's option", choices=("low", "high"),
                            kinds=("image", "udim"))
    setting = schema.setting_of(option)
    assert (setting.name, setting.kind, setting.default, setting.core) == ("dummy_level", "enum", "LOW", "dummy_level")
    assert setting.identifiers == ("LOW", "HIGH") and setting.targets == ("image", "udim")
    assert (setting.label, setting.help, setting.option) == ("Dummy Level", "A test's option", "--dummy-level")


def test_loading_the_settings_loads_no_numpy():
    code = ("import sys; sys.modules['bpy'] = None\n"
            "import mc_ao.schema, mc_ao.settings, mc_ao.rules\n"
            "assert 'numpy' not in sys.modules, sorted(m for m in sys.modules if 'numpy' in m)[:3]\n")
    subprocess.run([sys.executable, "-c", code], check=True)
