"""The user's path: build the zip, Install from Disk into a user repository, enable, bake, uninstall."""

import sys
from pathlib import Path

import pytest

from blender_helpers import ROOT, add_cube, add_plane, clean_scene, image_ao, select_only

pytestmark = pytest.mark.blender

REPO = "mc_ao_test"
ADDON = f"bl_ext.{REPO}.mc_ao"


@pytest.fixture
def built_zip(tmp_path):
    sys.path.insert(0, str(ROOT / "scripts"))
    try:
        import build_extension
    finally:
        sys.path.remove(str(ROOT / "scripts"))
    # This machine's platform only: pip downloads its two wheels into wheels/ once.
    (path,) = build_extension.build(platforms=["current"], output_dir=tmp_path / "dist")
    return path


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
