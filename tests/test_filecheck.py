"""mc_ao.filecheck: what a file is, which paths a run may write, and a .blend file read to its end marker."""

import gzip
import json
import subprocess
import sys
from pathlib import Path

import pytest

from mc_ao import filecheck

ROOT = Path(__file__).resolve().parent.parent
SAMPLES = sorted((ROOT / "sample_scenes").glob("*.blend"))  # zstd files saved by Blender 4.2


def test_importing_needs_no_bpy():
    code = "import sys; import mc_ao.filecheck; assert 'bpy' not in sys.modules"
    subprocess.run([sys.executable, "-c", code], check=True, cwd=ROOT)


def plain_blend(version_5=True):
    """A small uncompressed .blend file of either header layout: two blocks and the end marker."""
    if version_5:
        head = b"BLENDER17-01v0500"
        block = lambda code, data: code + b"\0" * 4 + b"\0" * 8 + len(data).to_bytes(8, "little") + b"\1" + b"\0" * 7 + data  # noqa: E731
    else:
        head = b"BLENDER-v402"
        block = lambda code, data: code + len(data).to_bytes(4, "little") + b"\0" * 8 + b"\0" * 8 + data  # noqa: E731
    return head + block(b"REND", b"x" * 40) + block(b"DNA1", b"y" * 100) + block(b"ENDB", b"")


@pytest.mark.parametrize("version_5", [True, False], ids=["blender-5", "blender-4"])
def test_a_blend_file_cut_anywhere_is_refused(tmp_path, version_5):
    data = plain_blend(version_5)
    path = tmp_path / "x.blend"
    path.write_bytes(data)
    filecheck.check_blend_complete(path)
    for cut in range(len(data)):
        path.write_bytes(data[:cut])
        with pytest.raises(filecheck.BlendFileError):
            filecheck.check_blend_complete(path)
    path.write_bytes(gzip.compress(data))
    filecheck.check_blend_complete(path)
    path.write_bytes(gzip.compress(data)[:-5])
    with pytest.raises(filecheck.BlendFileError):
        filecheck.check_blend_complete(path)


@pytest.mark.parametrize("sample", SAMPLES, ids=lambda p: p.name)
@pytest.mark.parametrize("zstandard", [True, False], ids=["decompressed", "seek-table"])
def test_blenders_compressed_files_cut_short_are_refused(tmp_path, monkeypatch, sample, zstandard):
    if not zstandard:
        monkeypatch.setitem(sys.modules, "zstandard", None)  # import fails: the seek table alone
    else:
        pytest.importorskip("zstandard")
    data = sample.read_bytes()
    path = tmp_path / "x.blend"
    filecheck.check_blend_complete(sample)
    for cut in [*range(len(data) - 64, len(data)), len(data) // 2, 100]:
        path.write_bytes(data[:cut])
        with pytest.raises(filecheck.BlendFileError):
            filecheck.check_blend_complete(path)


def test_file_kinds_come_from_the_contents(tmp_path):
    cases = {
        "a.blend": (plain_blend(), "a .blend file"),
        "fake.png": (plain_blend(), "a .blend file"),
        "b.png": (b"\x89PNG\r\n\x1a\n....", "a PNG image"),
        "s.json": (json.dumps({"mc_ao": "1", "objects": []}).encode(), "an mc_ao summary"),
        "t.json": (json.dumps({"mc_ao": "1", "tasks": []}).encode(), "an mc_ao batch summary"),
        "m.toml": (b"[[bake]]\nblend = 'a.blend'\n", "a file"),
        "other.json": (b'{"name": 1}', "a file"),
    }
    for name, (data, kind) in cases.items():
        (tmp_path / name).write_bytes(data)
        assert filecheck.file_kind(tmp_path / name) == kind, name
    assert filecheck.file_kind(tmp_path / "missing") is None
    assert filecheck.file_kind(tmp_path) == "a folder"


def test_an_output_may_not_be_an_input_another_output_or_another_kind(tmp_path):
    blend = tmp_path / "scene.blend"
    blend.write_bytes(plain_blend())
    summary = tmp_path / "summary.json"
    kinds = ("an mc_ao summary",)
    assert filecheck.output_problem(summary, "the summary", replaces=kinds) is None
    assert "input" in filecheck.output_problem(blend, "the summary", inputs=[(blend, "the .blend file")],
                                               replaces=kinds)
    link = tmp_path / "link.json"
    link.symlink_to(blend)
    assert "input" in filecheck.output_problem(link, "the summary", inputs=[(blend, "the .blend file")])
    assert "it is also the image" in filecheck.output_problem(
        tmp_path / "sub" / ".." / "a.png", "the summary", outputs=[(tmp_path / "a.png", "the image")])
    assert "a .blend file already there" in filecheck.output_problem(blend, "the summary", replaces=kinds)
    summary.write_text(json.dumps({"mc_ao": "0.1"}))
    assert filecheck.output_problem(summary, "the summary", replaces=kinds) is None


def test_an_empty_file_may_be_replaced(tmp_path):
    """``--summary-json "$(mktemp)"``: the empty file made for the output holds nothing to lose."""
    empty = tmp_path / "tmp.XXXX"
    empty.touch()
    assert filecheck.output_problem(empty, "the summary", replaces=("an mc_ao summary",)) is None
    assert filecheck.replace_problem(tmp_path / "x.png") is None
    (tmp_path / "x.png").touch()
    assert filecheck.replace_problem(tmp_path / "x.png") is None
    (tmp_path / "x.png").write_text("notes")
    assert "is a file, not a PNG image" in filecheck.replace_problem(tmp_path / "x.png")
