"""The layer contract (docs/CONTRIBUTING.md): imports run one way and only through the `mechsim` namespace.

- `mechanisms/` and `thermal/` import nothing of ours outside themselves;
- `dynamics/` imports neither `scenarios/` nor `benchmarks/`;
- nothing anywhere imports the bare folder names (`import dynamics`): `python -m pytest` from the root puts
  those folders on sys.path, where an installed mechsim would never see them.

Checked on the syntax tree of every Python file, relative imports resolved, lazy imports inside functions
included.
"""
import ast
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
SUBPACKAGES = ("mechanisms", "dynamics", "thermal", "scenarios", "benchmarks")
FORBIDDEN = {  # importer -> subpackages it must not import
    "mechanisms": {"dynamics", "thermal", "scenarios", "benchmarks"},
    "thermal": {"mechanisms", "dynamics", "scenarios", "benchmarks"},
    "dynamics": {"scenarios", "benchmarks"},
}


def python_files():
    for folder in (*SUBPACKAGES, "tests"):
        yield from sorted((ROOT / folder).rglob("*.py"))


def module_name(path: Path) -> list[str]:
    parts = list(path.relative_to(ROOT).with_suffix("").parts)
    if parts[-1] == "__init__":
        parts = parts[:-1]
    return ["mechsim", *parts]


def imported_modules(path: Path):
    """(line, absolute dotted name) of every import in the file."""
    tree = ast.parse(path.read_text(encoding="utf-8"), filename=str(path))
    here = module_name(path)
    package = here if path.name == "__init__.py" else here[:-1]
    for node in ast.walk(tree):
        if isinstance(node, ast.Import):
            for alias in node.names:
                yield node.lineno, alias.name
        elif isinstance(node, ast.ImportFrom):
            if node.level:
                base = package[: len(package) - (node.level - 1)]
                name = ".".join(base + ([node.module] if node.module else []))
            else:
                name = node.module or ""
            yield node.lineno, name


FILES = list(python_files())


def test_the_contract_sees_every_subpackage():
    seen = {p.relative_to(ROOT).parts[0] for p in FILES}
    assert set(SUBPACKAGES) <= seen


@pytest.mark.parametrize("path", FILES, ids=lambda p: str(p.relative_to(ROOT)))
def test_imports_follow_the_layers(path):
    layer = path.relative_to(ROOT).parts[0]
    problems = []
    for line, name in imported_modules(path):
        top = name.split(".")[0]
        if top in SUBPACKAGES:
            problems.append(f"line {line}: bare import of {name!r}; use 'mechsim.{name}'")
        parts = name.split(".")
        if parts[0] == "mechsim" and len(parts) > 1 and parts[1] in FORBIDDEN.get(layer, ()):
            problems.append(f"line {line}: {layer}/ must not import {name!r}")
    assert not problems, "\n".join(problems)
