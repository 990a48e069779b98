"""Untrusted names (object and image names) become file names that stay inside their folder."""

import os
import string

import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from core.files.filenames import MAX_STEM_BYTES, UnsafePathError, path_inside, safe_file_stem, unique_file_stems

HOSTILE = [
    "../x", "../../x", "/some/abs/path/x", "a/b", "..\\x", "C:x", "C:\\x", "..", ".", "...", "",
    " ", "x.", "x ", ".hidden", "CON", "con", "Aux.txt", "NUL", "COM1", "lpt9.png", "COM\u00b9",
    "a\x00b", "tab\there", "new\nline", "bell\x07", "a<b>c", 'quo"te', "pi|pe", "what?", "star*",
    "\u202eevil", "x" * 300, "\u00e9" * 300, "\U0001F600" * 100, "\u6728\u6750", "Stuhl_\u00fc",
    "a\u2028b", "\ud800",
]


def _is_safe_component(stem):
    assert stem and stem not in (".", "..")
    assert not stem.startswith(".")
    assert not stem.endswith((".", " "))
    assert not set('<>:"/\\|?*') & set(stem)
    assert all(ord(c) >= 32 and c not in "\x7f\u2028\u2029\u202e" for c in stem)
    assert len(stem.encode("utf-8", "surrogatepass")) <= MAX_STEM_BYTES
    base = stem.split(".", 1)[0].upper()
    assert base not in {"CON", "PRN", "AUX", "NUL"} and not (base[:3] in ("COM", "LPT") and len(base) == 4)
    return True


@pytest.mark.parametrize("name", HOSTILE)
def test_every_hostile_name_becomes_one_safe_component(name, tmp_path):
    stem = safe_file_stem(name)
    assert _is_safe_component(stem)
    path = path_inside(tmp_path, stem + "_AO.png")
    assert os.path.dirname(path) == str(tmp_path)
    # The longest suffix a bake adds still fits the 255-byte limit of a file name.
    long_name = stem + "_BentNormal_stderr.1001.tiff"
    assert len(long_name.encode("utf-8", "surrogatepass")) <= 255


def test_safe_names_are_kept_as_they_are():
    for name in ["Suzanne", "Chair_low", "rock.001", "Stuhl \u00fc", "\u6728\u6750", "a-b c"]:
        assert safe_file_stem(name) == name


def test_changed_names_stay_distinct_from_each_other_and_from_plain_names():
    names = ["a/b", "a_b", "a\\b", "a:b", "a?b", "a*b", "x" * 300, "x" * 301]
    stems = [safe_file_stem(n) for n in names]
    assert len(set(stems)) == len(names)
    assert safe_file_stem("a_b") == "a_b"
    assert safe_file_stem("a/b").startswith("a_b-")


def test_unique_stems_separate_names_that_differ_only_in_case():
    stems = unique_file_stems(["Cube", "cube", "CUBE", "Plane"])
    assert stems["Plane"] == "Plane"
    folded = [s.casefold() for s in stems.values()]
    assert len(set(folded)) == 4
    # The mapping of a name does not depend on the order or on the other names given with it.
    again = unique_file_stems(["CUBE", "Plane", "cube", "Cube"])
    assert again == stems


def test_path_inside_refuses_anything_but_one_component(tmp_path):
    for bad in ["../x.png", "a/b.png", "/etc/passwd", "..", ".", "", "a\\b.png", "x\x00.png"]:
        with pytest.raises(UnsafePathError):
            path_inside(tmp_path, bad)


def test_path_inside_refuses_a_link_that_leads_out_of_the_folder(tmp_path):
    outside = tmp_path / "outside"
    outside.mkdir()
    folder = tmp_path / "out"
    folder.mkdir()
    (folder / "Plane_AO.png").symlink_to(outside / "Plane_AO.png")
    with pytest.raises(UnsafePathError, match="outside the output folder"):
        path_inside(folder, "Plane_AO.png")


@settings(max_examples=300, deadline=None)
@given(st.text(alphabet=st.characters(codec="utf-8") | st.sampled_from(list("./\\:<>|?*" + string.whitespace)),
               max_size=400))
def test_any_text_gives_a_safe_component_inside_the_folder(name):
    stem = safe_file_stem(name)
    assert _is_safe_component(stem)
    root = "/tmp/mc_ao_out"
    joined = os.path.normpath(os.path.join(root, stem + "_AO.exr"))
    assert os.path.dirname(joined) == root
