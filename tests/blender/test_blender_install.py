"""The user's path: build the zip, Install from Disk into a user repository, enable, bake, uninstall."""

import sys
import zipfile
from pathlib import Path

import pytest

from blender_helpers import ROOT, add_cube, add_plane, clean_scene, image_ao, select_only

pytestmark = pytest.mark.blender

REPO = "mc_ao_test"
ADDON = f"bl_ext.{REPO}.mc_ao"


def _build_extension():
    sys.path.insert(0, str(ROOT / "scripts"))
    try:
        import build_extension
    finally:
        sys.path.remove(str(ROOT / "scripts"))
    return build_extension


@pytest.fixture
def built_zip(tmp_path):
    # This machine's platform only: pip downloads its two wheels into wheels/ once.
    (path,) = _build_extension().build(platforms=["current"], output_dir=tmp_path / "dist")
    return path


def test_own_zip_writer_matches_blenders_builder(bpy, tmp_path):
    """The fallback zip writer (for machines without Blender's builder) packs what Blender's does."""
    build_extension = _build_extension()
    (blenders,) = build_extension.build(["current"], tmp_path / "blender", builder="blender")
    (own,) = build_extension.build(["current"], tmp_path / "own", builder="self")
    assert blenders.name == own.name
    with zipfile.ZipFile(blenders) as a, zipfile.ZipFile(own) as b:
        assert sorted(a.namelist()) == sorted(b.namelist())
        assert a.read("blender_manifest.toml") == b.read("blender_manifest.toml")
        names = a.namelist()
    assert "__init__.py" in names and "core/bake.py" in names and "mc_ao/operators.py" in names
    assert not [n for n in names if n.startswith(("tests/", "scripts/", "bench/", "docs/", "sample_scenes/"))
                or "__pycache__" in n or n.endswith(".pyc")]
    wheels = [n for n in names if n.startswith("wheels/")]
    assert len(wheels) == 2  # cp311 and cp313 for this platform


@pytest.fixture
def user_repo(bpy, tmp_path):
    """A temporary local user repository, as Preferences > Get Extensions > Repositories > Add makes."""
    repos = bpy.context.preferences.extensions.repos
    repo = repos.new(name="MC AO Test", module=REPO, custom_directory=str(tmp_path / "repo"), source="USER")
    yield repo
    repos.remove(next(r for r in repos if r.module == REPO))


def test_install_from_disk_enable_bake_uninstall(bpy, built_zip, user_repo):
    assert not hasattr(bpy.types.Scene, "mc_ao"), "the checkout's add-on must not be registered here"
    result = bpy.ops.extensions.package_install_files(
        filepath=str(built_zip), repo=REPO, enable_on_install=True,
    )
    assert result == {"FINISHED"}
    assert ADDON in bpy.context.preferences.addons
    assert (Path(user_repo.directory) / "mc_ao" / "blender_manifest.toml").is_file()
    assert not (Path(user_repo.directory) / "mc_ao" / "tests").exists()
    # The wheel went where Blender puts extension wheels, and the bundled core is the one in use.
    site = Path(bpy.utils.user_resource("EXTENSIONS")) / ".local" / "lib"
    assert list(site.glob("python3*/site-packages/embreex")), "embreex wheel not installed"
    assert sys.modules[ADDON].mc_ao.corelink.CORE_NAME == f"{ADDON}.core"
    assert bpy.context.preferences.addons[ADDON].preferences.threads == 0

    scene = clean_scene(bpy)
    scene.mc_ao.resolution = 16
    scene.mc_ao.samples = 8
    ground = add_plane(bpy, "Ground", size=4)
    add_cube(bpy, "Block", size=1.0, location=(0, 0, 0.8))
    select_only(bpy, ground)
    assert bpy.ops.object.mc_ao_bake() == {"FINISHED"}
    ao, _ = image_ao(bpy.data.images["Ground_AO"])
    assert ao.shape == (16, 16) and ao.min() < 0.5 < ao.max()
    assert f"{ADDON}.core.bake" in sys.modules

    index = list(bpy.context.preferences.extensions.repos).index(user_repo)
    assert bpy.ops.extensions.package_uninstall(repo_index=index, pkg_id="mc_ao") == {"FINISHED"}
    assert ADDON not in bpy.context.preferences.addons
    assert not hasattr(bpy.types.Scene, "mc_ao")
    assert "mc_ao_bake" not in dir(bpy.ops.object)
