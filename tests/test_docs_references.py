"""Every reference into the theory chapter resolves, nothing points outside the repository, and every import in
the docs' Python examples runs.

Docstrings, messages and docs cite `docs/theory.md §G<n>` / `§K<n>`; each label must be a heading of
docs/theory.md (`### §G4.3 ...`) so a reader can find it. The team's working notes are not shipped, so no file
may send a reader to them.
"""
import re
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
THEORY = ROOT / "docs" / "theory.md"
LABEL = re.compile(r"§([GK]\d+(?:\.\d+)*)")
HEADING = re.compile(r"^#{1,6} §([GK]\d+(?:\.\d+)*)(?=\s)", re.MULTILINE)
NOTES = re.compile(r"\b(physics|kinematics|design)\.md\b")


def text_files():
    for path in sorted(ROOT.rglob("*")):
        parts = path.relative_to(ROOT).parts
        if path.suffix in (".py", ".md", ".toml") and path.is_file() and not any(
                p.startswith(".") or p in ("build", "dist", "__pycache__") or p.endswith(".egg-info") for p in parts):
            yield path


def headings() -> list[str]:
    return HEADING.findall(THEORY.read_text(encoding="utf-8"))


def test_theory_headings_are_unique():
    labels = headings()
    assert labels, "docs/theory.md has no §G/§K headings"
    assert len(labels) == len(set(labels)), sorted({x for x in labels if labels.count(x) > 1})


def test_every_cited_label_is_a_heading():
    known = set(headings())
    missing = {}
    for path in text_files():
        for label in LABEL.findall(path.read_text(encoding="utf-8", errors="replace")):
            if label not in known:
                missing.setdefault(label, str(path.relative_to(ROOT)))
    assert not missing, f"labels cited but not headings of docs/theory.md (label: first file): {missing}"


def test_the_chapters_cited_exist():
    for name in ("theory.md", "architecture.md"):
        assert (ROOT / "docs" / name).is_file(), name


def test_nothing_points_to_the_team_notes():
    hits = [f"{path.relative_to(ROOT)}:{i}" for path in text_files()
            for i, line in enumerate(path.read_text(encoding="utf-8", errors="replace").splitlines(), 1)
            if NOTES.search(line)]
    assert not hits, hits


PYTHON_BLOCK = re.compile(r"```python\n(.*?)```", re.DOTALL)
IMPORT = re.compile(r"^\s*(from\s+\S+\s+import\s+(?:\([^)]*\)|[^\n]*)|import\s+[^\n]+)", re.MULTILINE)


def test_the_python_examples_import_what_they_name():
    """Every import in a ```python example of the README and docs/ runs: a reader who copies one gets the module
    and the names it shows (docs/chain_dwell.md imported from a `mechanisms.chain_dwell` that no longer exists)."""
    failures = {}
    for path in [ROOT / "README.md", *sorted((ROOT / "docs").glob("*.md"))]:
        for block in PYTHON_BLOCK.findall(path.read_text(encoding="utf-8")):
            for statement in IMPORT.findall(block.replace("\\\n", " ")):     # continued lines joined
                statement = re.sub(r"\s*#[^\n]*", "", statement).strip()
                try:
                    exec(statement, {})
                except ImportError as exc:
                    failures.setdefault(path.name, []).append(f"{statement}: {exc}")
    assert not failures, failures
