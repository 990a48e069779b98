"""The README's promises: its Python example runs, its two commands are the ones CI and users run, and
every command of its quick start runs on the shipped sample scenes and writes the files it names."""

import importlib.util
import os
import platform
import re
import shlex
import shutil
import subprocess
import sys
from pathlib import Path

import pytest

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
    assert {Path(t.blend).name for t in tasks} == {"suzanne.blend", "room.blend", "analytic.blend", "rock.blend", "udim.blend"}
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


# --- The quick start, run: every command of it, on the shipped sample scenes, at a small size ------

#: Quick-start commands the test does not run, each with the reason. Every other command line of the
#: quick start runs (test_quick_start_runs); this list must name only commands the README has.
NOT_RUN = {
    "bash scripts/bootstrap.sh && .venv/bin/python -m pytest":
        "the test suite itself; .ci/run runs it (test_ci_runs_the_readme_test_command)",
}
#: Sizes a command runs at here: its own when smaller (what a command does is kept; only its cost falls).
SMALL = {"--resolution": 64, "--samples": 16}
#: The manifest's sizes when the batch's command runs here.
SMALL_MANIFEST = {"resolution": 32, "samples": 4}


def section(title, level=2):
    """The text of the README's section ``title`` (its heading line excluded), up to the next of its level."""
    mark = "#" * level + " "
    match = re.search(rf"^{mark}{re.escape(title)}\n(.*?)(?=^#{{1,{level}}} |\Z)", README, re.S | re.M)
    assert match, f"the README has no section {mark}{title}"
    return match.group(1)


def command_lines(text):
    """The command lines of ``text``: its indented code blocks' lines (a trailing backslash continues
    a line), without comments; fenced blocks (the Python example, JSON, TOML) are not commands."""
    text = re.sub(r"^```.*?^```", "", text, flags=re.S | re.M)
    lines, pending = [], ""
    for line in text.splitlines():
        if not line.startswith("    ") or line.strip().startswith("#"):
            continue
        line = pending + line.strip()
        if line.endswith("\\"):
            pending = line[:-1] + " "
            continue
        pending = ""
        lines.append(line)
    return lines


def quick_start():
    """(title, text, commands) of each part of the quick start: its opening, then each ### section."""
    text = section("Quick start")
    parts = re.split(r"^### (.+)\n", text, flags=re.M)
    named = [("(opening)", parts[0])] + list(zip(parts[1::2], parts[2::2]))
    return [(title, body, command_lines(body)) for title, body in named]


QUICK_START = quick_start()


def test_quick_start_has_a_command_for_each_feature():
    titles = " / ".join(title for title, _, commands in QUICK_START if commands)
    for feature in ("Blender", "error map", "UDIM", "Bent normals", "Colour attributes", "Selected to Active",
                    "library", "Python", "tests"):
        assert feature.lower() in titles.lower(), f"no quick start for {feature!r}: {titles}"
    assert all(commands for _, _, commands in QUICK_START), "a quick-start section without a command"
    every = [c for _, _, commands in QUICK_START for c in commands]
    assert set(NOT_RUN) <= set(every), "NOT_RUN names a command the quick start no longer has"


def test_commands_name_files_that_exist():
    """No placeholder in any command of the README (``scene.blend``, ``library.toml``): every .blend,
    .toml, .py, .sh, .yaml and .js path a command line names is a file of the checkout, or one an
    earlier command writes (under out/)."""
    for line in command_lines(README):
        for word in shlex.split(line):
            word = word.split("file://", 1)[-1]
            if re.search(r"\.(blend|toml|py|sh|yaml|js)$", word) and not word.startswith(("out/", "/")):
                assert (ROOT / word).is_file(), f"{word!r} in: {line}"


def shrink(args):
    """``args`` with every size in SMALL lowered to at most its value there."""
    args = list(args)
    for option, most in SMALL.items():
        if option in args:
            i = args.index(option) + 1
            args[i] = str(min(int(args[i]), most))
    return args


def mirror(root):
    """A copy of the checkout's layout in ``root`` made of links to its files, where the commands can
    write out/ and dist/ as on a fresh clone without touching the checkout; sample_scenes/ holds links
    to the scenes and the sample manifest at SMALL_MANIFEST's sizes."""
    skip = {".git", "out", "dist", "sample_scenes", "__pycache__", ".pytest_cache", ".hypothesis"}
    for path in ROOT.iterdir():
        if path.name not in skip and not path.name.startswith(".venv"):
            (root / path.name).symlink_to(path, target_is_directory=path.is_dir())
    scenes = root / "sample_scenes"
    scenes.mkdir()
    for path in (ROOT / "sample_scenes").iterdir():
        if path.suffix == ".blend" or path.suffix == ".py":
            (scenes / path.name).symlink_to(path)
    manifest = (ROOT / "sample_scenes" / "library.toml").read_text()
    for key, value in SMALL_MANIFEST.items():
        manifest, count = re.subn(rf"^{key} = \d+", f"{key} = {value}", manifest, flags=re.M)
        assert count, f"library.toml sets no {key}"
    (scenes / "library.toml").write_text(manifest)


def run_command(line, cwd):
    """Run a README command line in ``cwd`` with this Python for .venv/bin/python; its sizes shrunk."""
    line = line.removeprefix("bash scripts/bootstrap.sh && ")  # .venv is the environment running this
    args = shlex.split(line)
    assert args[0] == ".venv/bin/python", f"a quick-start command that is not .venv/bin/python: {line}"
    args = [sys.executable, *shrink(args[1:])]
    if "scripts/build_extension.py" in args:  # its zips into the mirror's dist/, its wheels where they live
        args += ["--output-dir", str(cwd / "dist"), "--wheel-dir", str(ROOT / "wheels")]
    # PWD as a shell sets it: Blender takes its working folder from $PWD before getcwd() (bpy 4.2 saves
    # a relative --save path there), and subprocess's cwd= leaves PWD as the parent's.
    env = {**os.environ, "PWD": str(cwd)}
    return subprocess.run(args, cwd=cwd, env=env, capture_output=True, text=True, timeout=900)


@pytest.mark.blender
@pytest.mark.parametrize("title", [title for title, _, _ in QUICK_START])
def test_quick_start_runs(title, tmp_path):
    """Each quick-start command runs on a fresh layout of the checkout (at most 64 x 64 and 16
    samples), exits with 0, warns of nothing, and writes every out/ and dist/ file its text names."""
    if importlib.util.find_spec("bpy") is None:
        pytest.skip("the quick start bakes .blend files: it needs the bpy module")
    _, text, commands = next(part for part in QUICK_START if part[0] == title)
    mirror(tmp_path)
    for line in commands:
        if line in NOT_RUN:
            continue
        proc = run_command(line, tmp_path)
        assert proc.returncode == 0, f"{line}\n{proc.stdout[-3000:]}\n{proc.stderr[-3000:]}"
        assert "warning" not in (proc.stdout + proc.stderr).lower(), f"{line}\n{proc.stdout}\n{proc.stderr}"
    named = re.findall(r"`((?:out|dist)/[^`<>*\s]+)`", text)
    if "linux_x64" not in f"{sys.platform}_{platform.machine()}".replace("x86_64", "x64"):
        named = [name for name in named if not name.startswith("dist/")]  # the README names Linux's zip
    for name in named:
        if not name.endswith("/"):
            assert (tmp_path / name).is_file(), f"{title}: the README says {name} is written"


def table_values(text):
    """The second column of every row of the Markdown tables in ``text``."""
    return [row[1].strip() for row in re.findall(r"^\|([^|\n]+)\|([^|\n]+)\|\s*$", text, re.M)]


def test_performance_figures_are_the_bench_tables():
    """What the README says about performance is the bench's current table (bench/README.md), value
    for value, so that a new bench run that changes a figure shows where the README must follow."""
    bench = (ROOT / "bench" / "README.md").read_text()
    current = table_values(re.search(r"^## Where mc_ao stands\n(.*?)(?=^## |\Z)", bench, re.S | re.M).group(1))
    ours = [v for v in table_values(section("Performance")) if v not in ("value", "---")]
    assert len(ours) >= 10
    assert [v for v in ours if v not in current] == [], "README figures that the bench's table does not have"


def anchor(heading, seen):
    """GitHub's anchor of a heading: lower case, punctuation dropped, spaces to hyphens, -1, -2 for repeats."""
    slug = re.sub(r"[^\w\- ]", "", heading.strip().lower()).replace(" ", "-")
    n = seen.get(slug, 0)
    seen[slug] = n + 1
    return f"{slug}-{n}" if n else slug


def test_links_within_the_readme_lead_somewhere():
    seen = {}
    anchors = {anchor(h, seen) for h in re.findall(r"^#+ (.+)$", re.sub(r"^```.*?^```", "", README, flags=re.S | re.M), re.M)}
    links = re.findall(r"\]\(#([^)]+)\)", README)
    assert links and [link for link in links if link not in anchors] == []
    for target in re.findall(r"\]\(([^)#:]+)\)", README):  # pictures and files
        assert (ROOT / target).exists(), target


def reference_commands():
    """The command lines after the quick start that need nothing but this checkout: no Blender
    executable, farm manager, scheduler or shared folder (those are the farm's, shown as examples)."""
    rest = README[README.index("\n## Sample scenes\n"):]
    return [line for line in command_lines(rest)
            if line.startswith(".venv/bin/python scripts/") and not re.search(r"https?://|tcp://|/shared/", line)]


def test_reference_has_local_commands():
    assert len(reference_commands()) >= 3, reference_commands()


@pytest.mark.blender
@pytest.mark.parametrize("line", reference_commands())
def test_reference_command_runs(line, tmp_path):
    """The reference's own commands (the script, the batch's local, Dask and Open Job Description
    runners) run as the quick start's do, small."""
    if importlib.util.find_spec("bpy") is None:
        pytest.skip("the commands bake .blend files: they need the bpy module")
    if "--runner dask" in line and importlib.util.find_spec("distributed") is None:
        pytest.skip("--runner dask needs distributed (requirements-batch.txt)")
    mirror(tmp_path)
    proc = run_command(line, tmp_path)
    assert proc.returncode == 0, f"{line}\n{proc.stdout[-3000:]}\n{proc.stderr[-3000:]}"
    assert "warning" not in (proc.stdout + proc.stderr).lower(), f"{line}\n{proc.stdout}\n{proc.stderr}"


def test_manifest_shown_is_the_sample_manifest():
    """The README's TOML is sample_scenes/library.toml as shipped (below its opening comment)."""
    shown = re.search(r"```toml\n(.*?)```", README, re.S).group(1)
    shipped = (ROOT / "sample_scenes" / "library.toml").read_text()
    assert shown.strip() == shipped[shipped.index("[defaults]"):].strip()


@pytest.mark.blender
def test_summary_json_example_has_the_scripts_fields(tmp_path):
    """The README's --summary-json example has the fields the script writes, for the command it names."""
    if importlib.util.find_spec("bpy") is None:
        pytest.skip("the command bakes a .blend file: it needs the bpy module")
    import json

    shown = json.loads(re.search(r"```json\n(.*?)```", README, re.S).group(1))
    text = section("The background script")
    line = next(l for l in command_lines(text) if l.startswith(".venv/bin/python"))
    assert "the second command" in text
    mirror(tmp_path)
    proc = run_command(line + " --summary-json out/summary.json", tmp_path)
    assert proc.returncode == 0, proc.stderr
    written = json.loads((tmp_path / "out" / "summary.json").read_text())
    assert sorted(shown) == sorted(written)
    assert sorted(shown["settings"]) == sorted(written["settings"])
    assert [sorted(o) for o in shown["objects"]] == [sorted(o) for o in written["objects"]]
    assert [o["object"] for o in shown["objects"]] == [o["object"] for o in written["objects"]]
    assert shown["blend"] == written["blend"] and shown["settings"]["samples"] == int(line.split("--samples ")[1].split()[0])


def script_options(script):
    out = subprocess.run([sys.executable, str(ROOT / "scripts" / script), "--help"], capture_output=True, text=True,
                         timeout=300, cwd=ROOT)
    assert out.returncode == 0, out.stderr
    return set(re.findall(r"(?<![\w-])(--[a-z][a-z0-9-]*)", out.stdout))


def test_options_the_readme_names_exist():
    """Every option of the Settings table and of the README's bake_ao.py and bake_batch.py command
    lines is one the script has (its --help lists it)."""
    if importlib.util.find_spec("bpy") is None:
        pytest.skip("the scripts' --help runs under the bpy module's Python")
    named = {"bake_ao.py": set(re.findall(r"`(--[a-z][a-z0-9-]*)", section("Settings"))), "bake_batch.py": set()}
    for line in command_lines(README):
        for script in named:
            if f"scripts/{script}" in line:
                after = line.split(f"scripts/{script}", 1)[1].split(" -- ", 1)[-1]
                named[script] |= set(re.findall(r"(?<![\w-])(--[a-z][a-z0-9-]*)", after))
    for script, options in named.items():
        assert options and options - script_options(script) == set(), script
