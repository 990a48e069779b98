"""The README's promises: its Python example runs, its two commands are the ones CI and users run."""

import re
import shutil
import subprocess
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent
README = (ROOT / "README.md").read_text()


def test_python_example_runs_and_writes_its_files(tmp_path):
    code = re.search(r"```python\n(.*?)```", README, re.S).group(1)
    out = subprocess.run([sys.executable, "-c", code], cwd=tmp_path, capture_output=True, text=True,
                         env={"PYTHONPATH": str(ROOT), "PATH": "/usr/bin:/bin"})
    assert out.returncode == 0, out.stderr
    assert "Mrays/s" in out.stdout
    assert (tmp_path / "out" / "ground_AO.exr").is_file() and (tmp_path / "out" / "ground_AO_stderr.exr").is_file()


def test_python_example_runs_as_a_file_from_the_repository_root(tmp_path):
    """As the README says to run it: saved as a file in the repository root (beside core/), run by the
    project's Python with nothing on PYTHONPATH. The root is mirrored in tmp_path (core/ linked) so
    that the example's out/ folder is not the checkout's."""
    code = re.search(r"```python\n(.*?)```", README, re.S).group(1)
    how = README[: README.index("```python")].rstrip().rsplit("\n\n", 1)[1]
    assert "repository root" in how and ".venv/bin/python example.py" in how, how
    (tmp_path / "example.py").write_text(code)
    try:
        (tmp_path / "core").symlink_to(ROOT / "core", target_is_directory=True)
    except OSError:  # no symbolic links here: a copy of the same files
        shutil.copytree(ROOT / "core", tmp_path / "core", ignore=shutil.ignore_patterns("__pycache__"))
    out = subprocess.run([sys.executable, "example.py"], cwd=tmp_path, capture_output=True, text=True,
                         env={"PATH": "/usr/bin:/bin"})
    assert out.returncode == 0, out.stderr
    assert "Mrays/s" in out.stdout and (tmp_path / "out" / "ground_AO.exr").is_file()


def test_sample_manifest_plans_every_sample_scene(tmp_path):
    """sample_scenes/library.toml, the batch's sample manifest, passes the batch's own checks (every
    setting against scripts/bake_ao.py's parser) and says how to run it."""
    from mc_ao_batch import manifest

    path = ROOT / "sample_scenes" / "library.toml"
    tasks = manifest.plan(path, tmp_path / "out")
    assert {Path(t.blend).name for t in tasks} == {"suzanne.blend", "room.blend", "analytic.blend", "rock.blend"}
    assert all(Path(t.blend).is_file() for t in tasks)
    assert "scripts/bake_batch.py sample_scenes/library.toml --output" in path.read_text()


def test_ci_runs_the_readme_test_command():
    command = "bash scripts/bootstrap.sh && .venv/bin/python -m pytest"
    assert command in README
    assert command in (ROOT / ".ci" / "run").read_text()


def test_readme_main_job_names_a_scene_that_exists():
    line = next(l for l in README.splitlines() if "scripts/bake_ao.py sample_scenes/" in l)
    blend = re.search(r"sample_scenes/\S+\.blend", line).group(0)
    assert (ROOT / blend).is_file()
