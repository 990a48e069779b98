"""The README's promises: its Python example runs, its two commands are the ones CI and users run."""

import re
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


def test_ci_runs_the_readme_test_command():
    command = "bash scripts/bootstrap.sh && .venv/bin/python -m pytest"
    assert command in README
    assert command in (ROOT / ".ci" / "run").read_text()


def test_readme_main_job_names_a_scene_that_exists():
    line = next(l for l in README.splitlines() if "scripts/bake_ao.py sample_scenes/" in l)
    blend = re.search(r"sample_scenes/\S+\.blend", line).group(0)
    assert (ROOT / blend).is_file()
