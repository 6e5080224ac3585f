"""What a wheel holds, from pyproject.toml's setuptools configuration and setup.py's package discovery (building
one is too slow for the suite):
only `mechsim` and its subpackages, every folder of ours with code in it, no tests; the docs that messages and
summary.json cite ship inside the package, and `mechsim docs` says where."""
import fnmatch
import re
import runpy
import tomllib
from pathlib import Path

from cli_helpers import invoke, one_line_error

ROOT = Path(__file__).resolve().parents[1]
CONFIG = tomllib.loads((ROOT / "pyproject.toml").read_text())["tool"]["setuptools"]
#: the packages setup.py finds (its setup() runs only as a script)
PACKAGES = runpy.run_path(str(ROOT / "setup.py"), run_name="setup_discovery")["PACKAGES"]
SKIP = {"tests", "build", "dist", "__pycache__"}


def folder_of(package: str) -> Path:
    assert package == "mechsim" or package.startswith("mechsim."), package
    return ROOT.joinpath(*package.split(".")[1:])


def shipped(path: Path) -> bool:
    """`path` (a file of the repository) is in the wheel: a module of a listed package, or its package data."""
    rel_parent = path.parent.relative_to(ROOT)
    package = ".".join(["mechsim", *rel_parent.parts])
    if package not in PACKAGES:
        return False
    if path.suffix == ".py":
        return True
    return any(fnmatch.fnmatch(path.name, g) for g in CONFIG.get("package-data", {}).get(package, []))


def test_only_mechsim_and_every_code_folder_no_tests():
    assert CONFIG["package-dir"] == {"mechsim": "."}
    code = {".".join(["mechsim", *p.parent.relative_to(ROOT).parts]) for p in ROOT.rglob("__init__.py")
            if not SKIP & set(p.relative_to(ROOT).parts) and not any(s.startswith(".") for s in p.parts)}
    assert "packages" not in CONFIG          # found, not listed: a new folder needs no pyproject edit
    listed = set(PACKAGES)
    assert len(listed) == len(PACKAGES)
    assert code <= listed, sorted(code - listed)                 # no code folder left out of the wheel
    assert all(folder_of(p).is_dir() for p in listed)
    assert not any("tests" in p.split(".") for p in listed)
    # folders listed without code are data only (the docs)
    assert {p for p in listed - code} == {"mechsim.docs", "mechsim.docs.report", "mechsim.docs.examples"}


def test_every_cited_document_ships_in_the_package():
    cited = set()
    for path in ROOT.rglob("*"):
        parts = set(path.relative_to(ROOT).parts)
        if path.suffix in (".py", ".toml") and path.is_file() and shipped(path) and not SKIP & parts:
            cited |= set(re.findall(r"docs/[\w/]+\.(?:md|png|csv|py)", path.read_text(encoding="utf-8")))
    assert "docs/theory.md" in cited and "docs/limits.md" in cited
    missing = sorted(c for c in cited if not (ROOT / c).is_file() or not shipped(ROOT / c))
    assert not missing, missing
    assert shipped(ROOT / "scenarios" / "builtin" / "geneva-lc1.toml")


def test_mechsim_docs_prints_where_a_document_is(tmp_path):
    r = invoke("docs", "theory")
    assert r.exit_code == 0 and Path(r.stdout.strip()) == ROOT / "docs" / "theory.md"
    r = invoke("docs")
    assert r.exit_code == 0 and Path(r.stdout.splitlines()[0]) == ROOT / "docs" and "limits" in r.stdout
    r = invoke("docs", "unknown-topic")
    assert r.exit_code == 2 and "unknown-topic" in one_line_error(r)
