"""Code and documentation say what things do, not when or why they were asked for: no issue numbers or
rounds of work in the shipped files, the tests, the bench's code and the docs (git keeps the history;
lab notes live in bench/LOG.md and bench/results/)."""

import re
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent
FOLDERS = ("core", "mc_ao", "mc_ao_batch", "scripts", "farm", "tests", "bench", "docs", "sample_scenes")
SUFFIXES = {".py", ".sh", ".md", ".toml", ".yaml", ".yml", ".json", ".txt", ".js"}
LAB_NOTES = (ROOT / "bench" / "LOG.md", ROOT / "bench" / "results")
# "issue 14", "issues 8 and 11", "issue #3", "round 4", "the issue's bounds"
HISTORY = re.compile(r"\bissues? #?\d+|\bround \d+\b(?! per)|\bthe issue's\b", re.IGNORECASE)


def _files():
    yield ROOT / "README.md"
    for folder in FOLDERS:
        for path in (ROOT / folder).rglob("*"):
            if path.suffix in SUFFIXES and path.is_file() and not any(
                    path == note or note in path.parents for note in LAB_NOTES):
                yield path


def test_no_file_names_an_issue_or_a_round():
    found = []
    for path in _files():
        if path == Path(__file__).resolve():
            continue
        for number, line in enumerate(path.read_text(errors="replace").splitlines(), 1):
            if HISTORY.search(line):
                found.append(f"{path.relative_to(ROOT)}:{number}: {line.strip()[:100]}")
    assert found == [], "history in the code or docs:\n" + "\n".join(found)
