"""mc_ao.filecheck.same_file: paths compared by the file they reach, also where no file is yet."""

import os

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
