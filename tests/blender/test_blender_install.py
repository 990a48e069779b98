"""The user's path: build the zip, Install from Disk into a user repository, enable, bake, uninstall."""

import shutil
import subprocess
import sys
import tomllib
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


def _shipped_on_disk():
    """What the zip must hold besides its wheels: the manifest, the add-on's entry, every file of its
    two packages (caches aside), the licence and the README; nothing else."""
    names = {"blender_manifest.toml", "__init__.py", "LICENSE", "README.md"}
    for package in ("core", "mc_ao"):
        names |= {p.relative_to(ROOT).as_posix() for p in (ROOT / package).rglob("*")
                  if p.is_file() and "__pycache__" not in p.parts and p.suffix != ".pyc"
                  and not p.name.startswith(".")}
    return names


def assert_allow_list(names):
    wheels = [n for n in names if n.startswith("wheels/")]
    assert set(names) - set(wheels) == _shipped_on_disk()
    assert len(wheels) == 2 and all(n.endswith(".whl") and n.count("/") == 1 for n in wheels)  # cp311, cp313


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
    assert "core/pipeline/run.py" in names and "mc_ao/operators.py" in names and "mc_ao/outputs/maps.py" in names
    assert_allow_list(names)


def test_allow_list_ignores_what_else_is_in_the_checkout(tmp_path, monkeypatch):
    """A folder or file added to the checkout (as mc_ao_batch/ and farm/ were) does not ship."""
    build_extension = _build_extension()
    source = tmp_path / "checkout"
    source.mkdir()
    for name in ("blender_manifest.toml", "__init__.py", "LICENSE", "README.md", "core", "mc_ao"):
        (shutil.copytree if (ROOT / name).is_dir() else shutil.copy2)(ROOT / name, source / name)
    for extra in ("mc_ao_batch/__init__.py", "farm/go.mod", "notes.txt", "core/__pycache__/x.cpython-311.pyc"):
        (source / extra).parent.mkdir(parents=True, exist_ok=True)
        (source / extra).write_text("not shipped")
    monkeypatch.setattr(build_extension, "ROOT", source)
    (path,) = build_extension.build(["current"], tmp_path / "dist", wheel_dir=ROOT / "wheels", builder="self")
    with zipfile.ZipFile(path) as zf:
        names = zf.namelist()
        manifest = zf.read("blender_manifest.toml").decode()
    assert_allow_list(names)
    # the shipped manifest's [build] keeps caches out; it is no deny-list of the checkout's folders
    assert tomllib.loads(manifest)["build"]["paths_exclude_pattern"] == list(build_extension.NEVER)


def _validate(cmd, zip_path):
    proc = subprocess.run([*cmd, "validate", str(zip_path)], capture_output=True, text=True, timeout=300)
    assert proc.returncode == 0 and "Success" in proc.stdout, proc.stdout + proc.stderr


def test_zip_validates_with_the_bpy_modules_checker(bpy, built_zip):
    """``extension validate``, as the bpy module carries it (Blender's own checker, plain Python)."""
    _validate([sys.executable, str(_build_extension().bpy_extension_builder())], built_zip)


@pytest.mark.skipif(shutil.which("blender") is None, reason="no Blender executable on PATH")
def test_zip_validates_with_blender(built_zip):
    """``blender --command extension validate``: the check Blender runs on a zip it installs."""
    _validate([shutil.which("blender"), "--factory-startup", "--command", "extension"], built_zip)


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
    assert f"{ADDON}.core.pipeline.run" in sys.modules
    # Worker processes from the installed extension: they import its core from the repository's folder
    # (not bl_ext, which a new interpreter cannot import) and the wheels' embreex; the same bits.
    core = sys.modules[f"{ADDON}.core"]
    import numpy as np

    P = np.array([[0, 0, 0], [1, 0, 0], [1, 1, 0], [0, 1, 0]], float)
    F = np.array([[0, 1, 2], [0, 2, 3]])
    plane = core.Mesh(P, F, uvs=P[F][:, :, :2], name="plane")
    lid = core.Mesh(P * [1, 1, 0] + [0.2, 0.2, 0.3], F, name="lid")
    one = core.bake_ao(plane, [lid], resolution=16, samples=8, threads=1)
    two = core.bake_ao(plane, [lid], resolution=16, samples=8, workers=2)
    assert np.array_equal(one.ao, two.ao) and np.array_equal(one.stderr, two.stderr)
    pool = sys.modules[f"{ADDON}.core.execution.pool"]._POOL
    assert pool is not None and all(w.alive for w in pool.workers)
    sys.modules[f"{ADDON}.core.execution.pool"].shutdown()

    index = list(bpy.context.preferences.extensions.repos).index(user_repo)
    assert bpy.ops.extensions.package_uninstall(repo_index=index, pkg_id="mc_ao") == {"FINISHED"}
    assert ADDON not in bpy.context.preferences.addons
    assert not hasattr(bpy.types.Scene, "mc_ao")
    assert "mc_ao_bake" not in dir(bpy.ops.object)
