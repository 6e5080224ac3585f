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


PRODUCT = [p for p in FILES if p.relative_to(ROOT).parts[0] != "tests"]


def import_source(node: ast.ImportFrom, module: list[str], is_package: bool) -> str:
    """The absolute dotted name a `from ... import` reads from (relative imports resolved)."""
    if not node.level:
        return node.module or ""
    package = module if is_package else module[:-1]
    base = package[: len(package) - (node.level - 1)]
    return ".".join(base + ([node.module] if node.module else []))


def reaching_into_others(text: str, module: list[str], is_package: bool = False) -> list[str]:
    """Private names imported from another of our modules, and assignments to an attribute of one of our
    imported modules (monkeypatching): both couple a module to another's internals."""
    tree = ast.parse(text)
    here = ".".join(module)
    ours: set[str] = set()          # local names bound to one of our modules or their members
    problems = []
    for node in ast.walk(tree):
        if isinstance(node, ast.ImportFrom):
            source = import_source(node, module, is_package)
            if source.startswith("mechsim") and source != here:
                for alias in node.names:
                    if alias.name.startswith("_"):
                        problems.append(f"line {node.lineno}: imports private {alias.name!r} from {source}")
                    ours.add(alias.asname or alias.name)
        elif isinstance(node, ast.Import):
            ours.update(alias.asname or alias.name.split(".")[0] for alias in node.names
                        if alias.name.startswith("mechsim"))
    for node in ast.walk(tree):
        targets = node.targets if isinstance(node, ast.Assign) else [node.target] if isinstance(
            node, (ast.AugAssign, ast.AnnAssign)) else []
        for target in targets:
            base = target
            while isinstance(base, ast.Attribute):
                base = base.value
            if isinstance(target, ast.Attribute) and isinstance(base, ast.Name) and base.id in ours:
                problems.append(f"line {node.lineno}: assigns {ast.unparse(target)} on one of our modules")
    return problems


@pytest.mark.parametrize("path", PRODUCT, ids=lambda p: str(p.relative_to(ROOT)))
def test_no_private_imports_or_monkeypatching(path):
    problems = reaching_into_others(path.read_text(encoding="utf-8"), module_name(path), path.name == "__init__.py")
    assert not problems, "\n".join(problems)


def test_the_private_import_check_catches_both_kinds():
    probe = ("from mechsim.dynamics.backends.ida import _hidden\nfrom ..dynamics import hybrid\n"
             "import mechsim.dynamics.backends.ida as ida\nida.IDA = None\nhybrid.MAX_STUCK += 1\n"
             "from .runner import _own_package_private\n")
    problems = reaching_into_others(probe, ["mechsim", "scenarios", "probe"])
    assert len(problems) == 4, problems
    assert "_hidden" in problems[0] and "_own_package_private" in problems[1]
    assert "ida.IDA" in problems[2] and "hybrid.MAX_STUCK" in problems[3]
