"""The README's and docs/' promises: the README is short and says what a newcomer needs first, its
Python example runs, its two commands are the ones CI and users run, and every command line of the
README and of docs/ runs on the shipped sample scenes and writes the files its text names (lines
that need what this checkout does not bring are marked, and run where that is here)."""

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
DOCS = {path.name: path.read_text() for path in sorted((ROOT / "docs").glob("*.md"))}
#: The README's most lines: what it is, requirements, the two commands, a line per feature, links.
MOST_LINES = 300
#: The section of the README that has a command for each feature.
FEATURES = "Every feature, one command each"
#: Features that must each have a section with a command there (a word of its title, lower case).
FEATURE_WORDS = ("blender", "error map", "denois", "udim", "bent normals", "colour attributes",
                 "selected to active", "thickness", "ground", "occluder collections", "channel packing", "atlas", "seams",
                 "python",
                 "library")
#: What a command line may need that this checkout does not bring (its "# needs ..." comment says
#: which), and how a line shows it needs it.
NEEDS = {
    "blender": re.compile(r"^blender "),
    "Dask scheduler": re.compile(r"--scheduler "),
    "Flamenco Manager": re.compile(r"--manager "),
}
#: Commands the test does not run, each with the reason.
NOT_RUN = {
    "bash scripts/bootstrap.sh && .venv/bin/python -m pytest":
        "the test suite itself; .ci/run runs it (test_ci_runs_the_readme_test_command)",
    '.venv/bin/python -m pytest -q -m "not blender and not slow"':
        "a part of this test suite (test_quick_subset_is_a_part_of_the_suite)",
}
#: Commands not run, by a pattern: each with the reason.
NOT_RUN_LIKE = {
    re.compile(r" -m bench\b"): "a bench run (minutes to hours; bench/README.md)",
}
#: Lines of other programs' output that the "no warning" check passes over, each with the reason.
NOT_OURS = {
    re.compile(r"^WARNING: Running pip as the 'root' user"): "pip's, where the tests run as root",
    re.compile(r"^\[notice\] "): "pip's note of its own newer release",
}
#: Sizes a command runs at here: its own when smaller (what a command does is kept; only its cost falls).
SMALL = {"--resolution": 64, "--samples": 16}
#: The manifest's sizes when the batch's commands run here.
SMALL_MANIFEST = {"resolution": 32, "samples": 4}


# --- reading Markdown ------------------------------------------------------------------------------

def without_fences(text):
    return re.sub(r"^```.*?^```", "", text, flags=re.S | re.M)


def section(text, title, level=2):
    """The text of ``text``'s section ``title`` (its heading line excluded), up to the next of its level."""
    mark = "#" * level + " "
    match = re.search(rf"^{mark}{re.escape(title)}\n(.*?)(?=^#{{1,{level}}} |\Z)", text, re.S | re.M)
    assert match, f"no section {mark}{title}"
    return match.group(1)


#: How a command line starts (an indented block's other lines are code or formulas shown).
COMMAND = re.compile(r"(\.venv[\w-]*/bin/|bash |blender |python3\.11 )")


def blocks(text):
    """The command blocks of ``text``: each indented code block (fenced blocks are not commands) as a
    list of (needs, line): its command lines (a trailing backslash continues a line) and what the
    "# needs ..." comment right above a line says it needs ("" when none). Other comments are skipped."""
    found, block, pending, needs = [], [], "", ""
    for line in without_fences(text).splitlines() + ["(end)"]:
        if not line.startswith("    "):
            if line.strip() == "" and block and not pending:
                continue  # a blank line inside an indented block is part of it only if more follows
            if block:
                found.append(block)
            block, pending, needs = [], "", ""
            continue
        stripped = line.strip()
        if stripped.startswith("#"):
            needs = stripped[1:].strip()[len("needs "):] if stripped.startswith("# needs ") else ""
            continue
        line = pending + stripped
        if line.endswith("\\"):
            pending = line[:-1] + " "
            continue
        pending = ""
        if COMMAND.match(line):  # not a snippet of Python or a formula
            block.append((needs, line))
        needs = ""
    return found


def command_lines(text):
    return [line for block in blocks(text) for _, line in block]


def need_of(needs):
    """The NEEDS key that a "# needs ..." comment names, or None."""
    needs = re.sub(r"^(a|an) ", "", needs.lower())
    return next((key for key in NEEDS if needs.startswith(key.lower())), None)


def features():
    """(title, text) of each ### section of the README's feature list."""
    parts = re.split(r"^### (.+)\n", section(README, FEATURES), flags=re.M)
    return list(zip(parts[1::2], parts[2::2]))


# --- the README's shape ---------------------------------------------------------------------------

def test_readme_is_short():
    assert len(README.splitlines()) <= MOST_LINES, f"README.md has {len(README.splitlines())} lines"


def test_readme_says_what_it_needs_before_the_commands():
    """Requirements come first: the Python, the disk for .venv, the suite's time and a quick subset."""
    requirements = section(README, "Requirements")
    assert README.index("## Requirements") < README.index("## Quick start") < README.index("## Run the tests")
    for needed in ("Python 3.11", "GB", "minutes", "2 cores"):
        assert needed in requirements, needed
    assert [line for line in command_lines(requirements) if "pytest" in line], "no quick subset to run first"


def test_quick_subset_is_a_part_of_the_suite():
    """The quick subset's markers exist (pytest.ini) and it leaves Blender out: it runs without bpy."""
    line = next(line for line in command_lines(section(README, "Requirements")) if "pytest" in line)
    marks = set(re.findall(r"not (\w+)", line))
    declared = set(re.findall(r"^\s+(\w+):", (ROOT / "pytest.ini").read_text(), re.M))
    assert marks and marks <= declared and "blender" in marks, (marks, declared)


def test_ci_runs_the_readme_test_command():
    command = "bash scripts/bootstrap.sh && .venv/bin/python -m pytest"
    assert command_lines(section(README, "Run the tests")) == [command]
    assert command in (ROOT / ".ci" / "run").read_text()


def test_readme_main_job_names_a_scene_that_exists():
    (line,) = command_lines(section(README, "Quick start"))
    assert line.startswith("bash scripts/bootstrap.sh && .venv/bin/python scripts/bake_ao.py sample_scenes/")
    blend = re.search(r"sample_scenes/\S+\.blend", line).group(0)
    assert (ROOT / blend).is_file()


def test_every_feature_has_a_command():
    titles = [title for title, _ in features()]
    for word in FEATURE_WORDS:
        assert any(word in title.lower() for title in titles), f"no feature section for {word!r}: {titles}"
    assert all(command_lines(text) for _, text in features()), "a feature section without a command"


def test_lines_that_need_more_are_marked():
    """A command that needs a Blender on the PATH, a Dask scheduler or a Flamenco Manager says so in
    a "# needs ..." comment, and every such comment names one of those."""
    for name, text in [("README.md", README), *DOCS.items()]:
        for block in blocks(text):
            for needs, line in block:
                wanted = [key for key, pattern in NEEDS.items() if pattern.search(line)]
                assert wanted == ([need_of(needs)] if needs else []), f"{name}: {needs!r} for: {line}"


def test_every_command_writes_into_a_folder_of_its_own():
    """Feature commands write under out/<folder>/, each its own (a batch runner into another's folder
    would find every task done and bake nothing); the quick start alone writes into out/."""
    runners, bare = {}, []
    for text in [README, *DOCS.values()]:
        for line in command_lines(text):
            args = shlex.split(line)
            if "--output" not in args:
                continue
            folder = args[args.index("--output") + 1].rstrip("/")
            if folder == "out":
                bare.append(line)
            if "scripts/bake_batch.py" in args and not folder.startswith("/shared"):
                runner = args[args.index("--runner") + 1] if "--runner" in args else "local"
                runners.setdefault(folder, set()).add(runner)
    assert bare == command_lines(section(README, "Quick start")), bare
    assert {folder: r for folder, r in runners.items() if len(r) > 1} == {}


# --- the Python example ---------------------------------------------------------------------------

def python_example():
    return re.search(r"```python\n(.*?)```", README, re.S).group(1)


def test_python_example_runs_and_writes_its_files(tmp_path):
    out = subprocess.run([sys.executable, "-c", python_example()], cwd=tmp_path, capture_output=True, text=True,
                         env={"PYTHONPATH": str(ROOT), "PATH": "/usr/bin:/bin"})
    assert out.returncode == 0, out.stderr
    assert "Mrays/s" in out.stdout
    assert (tmp_path / "out" / "ground_AO.exr").is_file() and (tmp_path / "out" / "ground_AO_stderr.exr").is_file()


def test_python_example_runs_as_a_file_from_the_repository_root(tmp_path):
    """As the README says to run it: saved as a file in the repository root (beside core/), run by the
    project's Python with nothing on PYTHONPATH. The root is mirrored in tmp_path (core/ linked) so
    that the example's out/ folder is not the checkout's."""
    how = README[: README.index("```python")].rstrip().rsplit("\n\n", 1)[1]
    assert "repository root" in how and ".venv/bin/python example.py" in how, how
    (tmp_path / "example.py").write_text(python_example())
    try:
        (tmp_path / "core").symlink_to(ROOT / "core", target_is_directory=True)
    except OSError:  # no symbolic links here: a copy of the same files
        shutil.copytree(ROOT / "core", tmp_path / "core", ignore=shutil.ignore_patterns("__pycache__"))
    out = subprocess.run([sys.executable, "example.py"], cwd=tmp_path, capture_output=True, text=True,
                         env={"PATH": "/usr/bin:/bin"})
    assert out.returncode == 0, out.stderr
    assert "Mrays/s" in out.stdout and (tmp_path / "out" / "ground_AO.exr").is_file()


# --- running the commands -------------------------------------------------------------------------

def test_commands_name_files_that_exist():
    """No placeholder in any command (``scene.blend``, ``library.toml``): every .blend, .toml, .py,
    .sh, .yaml and .js path a command line names is a file of the checkout, or one an earlier command
    writes (under out/)."""
    for name, text in [("README.md", README), *DOCS.items()]:
        for line in command_lines(text):
            for word in shlex.split(line):
                word = word.split("file://", 1)[-1]
                if re.search(r"\.(blend|toml|py|sh|yaml|js)$", word) and not word.startswith(("out/", "/")):
                    assert (ROOT / word).is_file(), f"{name}: {word!r} in: {line}"


def shrink(args):
    """``args`` with every size in SMALL lowered to at most its value there. A bake into another image's
    channel (--into) keeps its resolution: that image's size decides it."""
    args = list(args)
    for option, most in SMALL.items():
        if option in args and not (option == "--resolution" and "--into" in args):
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
    (root / ".venv").mkdir()
    (root / ".venv" / "bin").symlink_to(Path(sys.executable).parent, target_is_directory=True)
    scenes = root / "sample_scenes"
    scenes.mkdir()
    for path in (ROOT / "sample_scenes").iterdir():
        if path.suffix in (".blend", ".py"):
            (scenes / path.name).symlink_to(path)
    manifest = (ROOT / "sample_scenes" / "library.toml").read_text()
    for key, value in SMALL_MANIFEST.items():
        manifest, count = re.subn(rf"^{key} = \d+", f"{key} = {value}", manifest, flags=re.M)
        assert count, f"library.toml sets no {key}"
    (scenes / "library.toml").write_text(manifest)


def run_command(line, cwd):
    """Run a command line in ``cwd``: this Python for .venv/bin/python (.venv/bin/ is this Python's
    folder in the mirror), its sizes shrunk."""
    line = line.removeprefix("bash scripts/bootstrap.sh && ")  # .venv is the environment running this
    env = {**os.environ, "PWD": str(cwd)}
    if "&&" in line:  # a line of several steps: the shell's (the mirror's .venv/bin is this Python's)
        return subprocess.run(["bash", "-c", line], cwd=cwd, env=env, capture_output=True, text=True, timeout=900)
    args = shlex.split(line)
    if args[0] == ".venv/bin/python":
        args = [sys.executable, *shrink(args[1:])]
    elif args[0] == "blender":
        args = [shutil.which("blender"), *shrink(args[1:])]
    else:
        assert args[0].startswith(".venv/bin/"), f"a command that is not the project's: {line}"
    if "scripts/build_extension.py" in args:  # its zips into the mirror's dist/, its wheels where they live
        args += ["--output-dir", str(cwd / "dist"), "--wheel-dir", str(ROOT / "wheels")]
    # env's PWD as a shell sets it: Blender takes its working folder from $PWD before getcwd() (bpy 4.2
    # saves a relative --save path there), and subprocess's cwd= leaves PWD as the parent's.
    return subprocess.run(args, cwd=cwd, env=env, capture_output=True, text=True, timeout=900)


def ours(proc):
    """What a command printed, without the lines of NOT_OURS."""
    return "\n".join(line for line in (proc.stdout + proc.stderr).splitlines()
                     if not any(pattern.search(line) for pattern in NOT_OURS))


def not_run(line):
    """Why the test does not run ``line`` (NOT_RUN, NOT_RUN_LIKE), or None."""
    return NOT_RUN.get(line) or next((why for pattern, why in NOT_RUN_LIKE.items() if pattern.search(line)), None)


def runnable(needs):
    """Why a block whose lines need ``needs`` cannot run here, or None."""
    need = need_of(needs)
    if need == "blender":
        return None if shutil.which("blender") else "no blender on the PATH"
    return f"needs a {need}" if need else None


def all_blocks():
    """(id, file, block, text whose out/ and dist/ files it must write) of every command block: the
    README's by section (the quick start and each feature), docs/ by page."""
    found = [("README: Quick start", "README.md", block, section(README, "Quick start"))
             for block in blocks(section(README, "Quick start"))]
    for title, text in features():
        found += [(f"README: {title}", "README.md", block, text) for block in blocks(text)]
    for name, text in DOCS.items():
        found += [(f"{name} {i}: {block[0][1][:70]}", name, block, "") for i, block in enumerate(blocks(text))]
    return found


BLOCKS = all_blocks()


@pytest.mark.blender
@pytest.mark.parametrize("ident", [ident for ident, *_ in BLOCKS])
def test_command_block_runs(ident, tmp_path):
    """Each command block runs in a fresh layout of the checkout (at most 64 x 64 and 16 samples), its
    lines in order; each exits with 0 and warns of nothing, and a README section's out/ and dist/
    files that its text names are written. Lines that need what is not here are skipped, saying so."""
    if importlib.util.find_spec("bpy") is None:
        pytest.skip("the commands bake .blend files: they need the bpy module")
    _, _, block, text = next(entry for entry in BLOCKS if entry[0] == ident)
    lines = [(needs, line) for needs, line in block if not_run(line) is None]
    if not lines:
        pytest.skip("; ".join(not_run(line) for _, line in block))
    skipped = [f"{line} ({runnable(needs)})" for needs, line in lines if runnable(needs)]
    if len(skipped) == len(lines):
        pytest.skip("; ".join(skipped))
    mirror(tmp_path)
    for needs, line in lines:
        if runnable(needs):
            continue
        proc = run_command(line, tmp_path)
        assert proc.returncode == 0, f"{line}\n{proc.stdout[-3000:]}\n{proc.stderr[-3000:]}"
        assert "warning" not in ours(proc).lower(), f"{line}\n{proc.stdout}\n{proc.stderr}"
    for _, line in lines:  # a batch runner bakes into its own folder (one into another's bakes nothing)
        args = shlex.split(line)
        if "scripts/bake_batch.py" in args and args[args.index("--output") + 1].startswith("out/"):
            if (args[args.index("--runner") + 1] if "--runner" in args else "local") in ("local", "dask", "openjd"):
                folder = tmp_path / args[args.index("--output") + 1]
                assert (folder / "suzanne" / "Suzanne_AO.png").is_file(), f"{line}: baked nothing into {folder}"
    named = re.findall(r"`((?:out|dist)/[^`<>*\s]+)`", text)
    if "linux_x64" not in f"{sys.platform}_{platform.machine()}".replace("x86_64", "x64"):
        named = [name for name in named if not name.startswith("dist/")]  # the README names Linux's zip
    for name in named:
        if not name.endswith("/"):
            assert (tmp_path / name).is_file(), f"{ident}: the text says {name} is written"


# --- docs/ ----------------------------------------------------------------------------------------

def test_sample_manifest_plans_every_sample_scene(tmp_path):
    """sample_scenes/library.toml, the batch's sample manifest, passes the batch's own checks (every
    setting against scripts/bake_ao.py's parser) and says how to run it."""
    from mc_ao_batch import manifest

    path = ROOT / "sample_scenes" / "library.toml"
    tasks = manifest.plan(path, tmp_path / "out")
    assert {Path(t.blend).name for t in tasks} == {"suzanne.blend", "room.blend", "analytic.blend", "rock.blend", "udim.blend",
                                                   "props.blend", "atlas.blend"}
    assert all(Path(t.blend).is_file() for t in tasks)
    assert "scripts/bake_batch.py sample_scenes/library.toml --output" in path.read_text()


def table_values(text):
    """The second column of every row of the Markdown tables in ``text``."""
    return [row[1].strip() for row in re.findall(r"^\|([^|\n]+)\|([^|\n]+)\|\s*$", text, re.M)]


def test_performance_figures_are_the_bench_tables():
    """What docs/performance.md says is the bench's current table (bench/README.md), value for value,
    so that a new bench run that changes a figure shows where the page must follow."""
    bench = (ROOT / "bench" / "README.md").read_text()
    current = table_values(re.search(r"^## Where mc_ao stands\n(.*?)(?=^## |\Z)", bench, re.S | re.M).group(1))
    ours = [v for v in table_values(DOCS["performance.md"]) if v not in ("value", "---")]
    assert len(ours) >= 10
    assert [v for v in ours if v not in current] == [], "figures that the bench's table does not have"


def anchor(heading, seen):
    """GitHub's anchor of a heading: lower case, punctuation dropped, spaces to hyphens, -1, -2 for repeats."""
    slug = re.sub(r"[^\w\- ]", "", heading.strip().lower()).replace(" ", "-")
    n = seen.get(slug, 0)
    seen[slug] = n + 1
    return f"{slug}-{n}" if n else slug


def anchors(path):
    seen = {}
    return {anchor(h, seen) for h in re.findall(r"^#+ (.+)$", without_fences(path.read_text()), re.M)}


@pytest.mark.parametrize("page", ["README.md", *[f"docs/{name}" for name in DOCS]])
def test_links_lead_somewhere(page):
    """Every link of the README and of docs/ leads to a file of the checkout, and an anchor to a
    heading of its page."""
    path = ROOT / page
    for target in re.findall(r"\]\(([^)\s]+)\)", path.read_text()):
        if re.match(r"[a-z]+://", target):
            continue
        file, _, fragment = target.partition("#")
        linked = (path.parent / file).resolve() if file else path
        assert linked.exists(), f"{page}: {target}"
        if fragment and linked.suffix == ".md":
            assert fragment in anchors(linked), f"{page}: {target}"


def test_docs_are_linked_from_the_readme():
    linked = set(re.findall(r"\]\(docs/([\w.-]+\.md)", README))
    assert set(DOCS) - linked == set(), "pages of docs/ that the README does not link"


def test_settings_page_names_every_setting():
    """docs/settings.md's table has a row for every setting of the panel (mc_ao.schema.SETTINGS: its
    label, as the panel shows it), which names the setting's script option where it has one."""
    from mc_ao import schema

    rows = re.findall(r"^\|.*\|\s*$", DOCS["settings.md"], re.M)
    missing = []
    for setting in schema.SETTINGS:
        named = [row for row in rows if re.search(rf"(^|[ ,(]){re.escape(setting.label)}\b", row.strip())]
        if not named or (setting.option and not any(setting.option in row for row in named)):
            missing.append(f"{setting.label} ({setting.option})")
    assert missing == [], "settings that docs/settings.md leaves out"


def test_manifest_shown_is_the_sample_manifest():
    """docs/batch.md's TOML is sample_scenes/library.toml as shipped (below its opening comment)."""
    shown = re.search(r"```toml\n(.*?)```", DOCS["batch.md"], re.S).group(1)
    shipped = (ROOT / "sample_scenes" / "library.toml").read_text()
    assert shown.strip() == shipped[shipped.index("[defaults]"):].strip()


@pytest.mark.blender
def test_summary_json_example_has_the_scripts_fields(tmp_path):
    """docs/script.md's --summary-json example has the fields the script writes, for the command it names."""
    if importlib.util.find_spec("bpy") is None:
        pytest.skip("the command bakes a .blend file: it needs the bpy module")
    import json

    text = DOCS["script.md"]
    shown = json.loads(re.search(r"```json\n(.*?)```", text, re.S).group(1))
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
    assert [Path(f).relative_to("/abs") for o in shown["objects"] for f in o["files"]] == [
        Path(f).relative_to(tmp_path.resolve()) for o in written["objects"] for f in o["files"]]


def script_options(script):
    out = subprocess.run([sys.executable, str(ROOT / "scripts" / script), "--help"], capture_output=True, text=True,
                         timeout=300, cwd=ROOT)
    assert out.returncode == 0, out.stderr
    return set(re.findall(r"(?<![\w-])(--[a-z][a-z0-9-]*)", out.stdout))


def test_options_the_docs_name_exist():
    """Every option of docs/settings.md's table and of every bake_ao.py and bake_batch.py command line
    is one the script has (its --help lists it)."""
    if importlib.util.find_spec("bpy") is None:
        pytest.skip("the scripts' --help runs under the bpy module's Python")
    named = {"bake_ao.py": set(re.findall(r"`(--[a-z][a-z0-9-]*)", DOCS["settings.md"])), "bake_batch.py": set()}
    for text in [README, *DOCS.values()]:
        for line in command_lines(text):
            for script in named:
                if f"scripts/{script}" in line:
                    after = line.split(f"scripts/{script}", 1)[1].split(" -- ", 1)[-1]
                    named[script] |= set(re.findall(r"(?<![\w-])(--[a-z][a-z0-9-]*)", after))
    for script, options in named.items():
        assert options and options - script_options(script) == set(), script
