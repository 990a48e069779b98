"""mc_ao.filecheck.same_file and the core's core.files.filenames.same_file: paths compared by the file
they reach, also where no file is yet; the core's AO and standard-error files never one file."""

import os
from types import SimpleNamespace

import numpy as np
import pytest

from core.base.errors import SettingsError
from core.files import filenames, imageio
from mc_ao.filecheck import file_key, output_problem, same_file


def test_existing_files_are_compared_by_the_file_they_reach(tmp_path):
    (tmp_path / "real").mkdir()
    (tmp_path / "real" / "a.png").write_bytes(b"a")
    (tmp_path / "real" / "b.png").write_bytes(b"b")
    os.symlink(tmp_path / "real", tmp_path / "link")
    os.link(tmp_path / "real" / "a.png", tmp_path / "hard.png")
    assert same_file(tmp_path / "link" / "a.png", tmp_path / "real" / "a.png")
    assert same_file(tmp_path / "real" / ".." / "link" / "a.png", tmp_path / "hard.png")
    assert not same_file(tmp_path / "link" / "b.png", tmp_path / "real" / "a.png")


def test_outputs_not_written_yet_are_compared_by_their_folders_real_path_and_name(tmp_path):
    (tmp_path / "real").mkdir()
    os.symlink(tmp_path / "real", tmp_path / "link")
    assert same_file(tmp_path / "link" / "new.png", tmp_path / "real" / "new.png")
    assert same_file(tmp_path / "link" / "NEW.png", tmp_path / "real" / "new.png")  # one file where case is ignored
    assert not same_file(tmp_path / "link" / "new.png", tmp_path / "real" / "other.png")
    (tmp_path / "real" / "there.png").write_bytes(b"x")
    assert not same_file(tmp_path / "link" / "there.png", tmp_path / "real" / "new.png")
    assert file_key(tmp_path / "link" / "there.png")[0] == "file" and file_key(tmp_path / "x.png")[0] == "path"


def test_an_output_through_a_link_is_refused_as_an_input_or_another_output(tmp_path):
    (tmp_path / "real").mkdir()
    os.symlink(tmp_path / "real", tmp_path / "link")
    (tmp_path / "real" / "scene.blend").write_bytes(b"BLENDER-v500")
    problem = output_problem(tmp_path / "link" / "scene.blend", "the summary",
                             inputs=[(tmp_path / "real" / "scene.blend", "the .blend file")])
    assert problem == "it is the .blend file, an input of this run"
    problem = output_problem(tmp_path / "link" / "s.json", "the summary", outputs=[(tmp_path / "real" / "s.json", "x")])
    assert problem == "it is also x"


@pytest.mark.parametrize("same", [same_file, filenames.same_file], ids=["mc_ao", "core"])
def test_the_add_on_and_the_core_compare_paths_by_one_rule(tmp_path, same):
    (tmp_path / "real").mkdir()
    (tmp_path / "real" / "a.png").write_bytes(b"a")
    os.symlink(tmp_path / "real", tmp_path / "link")
    os.link(tmp_path / "real" / "a.png", tmp_path / "hard.png")
    cases = [(tmp_path / "link" / "a.png", tmp_path / "real" / "a.png", True),
             (tmp_path / "real" / ".." / "link" / "a.png", tmp_path / "hard.png", True),
             (tmp_path / "link" / "new.png", tmp_path / "real" / "new.png", True),
             (tmp_path / "link" / "NEW.png", tmp_path / "real" / "new.png", True),
             (tmp_path / "link" / "new.png", tmp_path / "real" / "other.png", False),
             (tmp_path / "link" / "a.png", tmp_path / "real" / "new.png", False)]
    for a, b, want in cases:
        assert same(a, b) == want == same(str(b), str(a)), (a, b)


def test_the_cores_ao_and_stderr_files_reaching_one_file_are_refused_and_nothing_is_written(tmp_path):
    rng = np.random.default_rng(1)
    result = SimpleNamespace(ao=rng.random((4, 6), dtype=np.float32),
                             stderr=(rng.random((4, 6), dtype=np.float32) * 0.01))
    (tmp_path / "real").mkdir()
    os.symlink(tmp_path / "real", tmp_path / "link")
    with pytest.raises(SettingsError, match="same path"):  # neither there yet
        imageio.write_ao(tmp_path / "real" / "ao.exr", result, stderr_path=tmp_path / "link" / "ao.exr")
    assert os.listdir(tmp_path / "real") == []
    imageio.write_ao(tmp_path / "real" / "ao.exr", result)
    before = (tmp_path / "real" / "ao.exr").read_bytes()
    with pytest.raises(SettingsError, match="reaches it"):  # an earlier bake's file: kept as it was
        imageio.write_ao(tmp_path / "real" / "ao.exr", result, stderr_path=tmp_path / "link" / "ao.exr")
    assert (tmp_path / "real" / "ao.exr").read_bytes() == before and os.listdir(tmp_path / "real") == ["ao.exr"]
