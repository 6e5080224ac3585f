"""The layer contract (docs/architecture.md, "The import rule"): imports run one way and only through the
`mechsim` namespace.

- `mechanisms/` and `thermal/` import nothing of ours outside themselves, but the leaves: the one emitter from
  sympy to callables (`mechsim.dynamics.codegen`) and the one quadrature between instants
  (`mechsim.dynamics.quadrature`), which import nothing of ours;
- `dynamics/` imports neither `scenarios/` nor `benchmarks/`;
- the scenario pipeline (every module of `scenarios/` but the studies and the two faces, api.py and cli.py)
  never imports `scenarios/studies/`;
- nothing but `scenarios/cli.py` and `benchmarks/` itself imports `benchmarks/` (tests aside);
- the product's modules import each other without a circle (but the known ones listed below);
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
#: modules every layer may import: leaves below all of them (they import nothing of ours, checked below)
LEAVES = ("mechsim.dynamics.codegen", "mechsim.dynamics.quadrature")
#: the faces of the studies: the only modules outside scenarios/studies/ that import it
STUDY_FACES = ("scenarios/api.py", "scenarios/cli.py")
#: the one product module outside benchmarks/ that imports it (`mechsim bench`, `mechsim report`)
BENCHMARK_FACES = ("scenarios/cli.py",)


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
        if (parts[0] == "mechsim" and len(parts) > 1 and parts[1] in FORBIDDEN.get(layer, ())
                and name not in LEAVES):
            problems.append(f"line {line}: {layer}/ must not import {name!r}")
        if parts[:3] == ["mechsim", "scenarios", "studies"] and pipeline(path):
            problems.append(f"line {line}: the scenario pipeline must not import the studies ({name!r})")
        if parts[:2] == ["mechsim", "benchmarks"] and not may_import_benchmarks(path):
            problems.append(f"line {line}: only {', '.join(BENCHMARK_FACES)} and benchmarks/ import {name!r}")
    assert not problems, "\n".join(problems)


@pytest.mark.parametrize("leaf", LEAVES)
def test_the_shared_leaves_import_nothing_of_ours(leaf):
    path = ROOT.joinpath(*leaf.split(".")[1:]).with_suffix(".py")
    ours = [f"line {line}: {name}" for line, name in imported_modules(path) if name.split(".")[0] == "mechsim"]
    assert not ours, ours


def test_no_lambdify_but_the_emitter():
    """Every way from sympy to a callable goes through the one emitter (dynamics/codegen.py, by target); the
    benchmarks, which measure other ways on purpose, aside."""
    emitter = ROOT.joinpath(*LEAVES[0].split(".")[1:]).with_suffix(".py")
    offenders = []
    for path in PRODUCT:
        if path == emitter or path.relative_to(ROOT).parts[0] == "benchmarks":
            continue
        for node in ast.walk(ast.parse(path.read_text(encoding="utf-8"))):
            if isinstance(node, ast.Attribute) and node.attr in ("lambdify", "ufuncify", "autowrap"):
                offenders.append(f"{path.relative_to(ROOT)}:{node.lineno}: {ast.unparse(node)}")
            elif isinstance(node, ast.ImportFrom) and (node.module or "").startswith("sympy") and any(
                    a.name in ("lambdify", "ufuncify", "autowrap") for a in node.names):
                offenders.append(f"{path.relative_to(ROOT)}:{node.lineno}: from {node.module} import ...")
    assert not offenders, offenders


def pipeline(path: Path) -> bool:
    """A module of the scenario pipeline: in scenarios/, not a study, not one of the studies' faces."""
    rel = path.relative_to(ROOT)
    return rel.parts[0] == "scenarios" and rel.parts[1] != "studies" and rel.as_posix() not in STUDY_FACES


def may_import_benchmarks(path: Path) -> bool:
    rel = path.relative_to(ROOT)
    return rel.parts[0] in ("benchmarks", "tests") or rel.as_posix() in BENCHMARK_FACES


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


#: circles that exist and are known, to be taken apart (each is really one unit): the independent references
#: import their mechanism's class; the derived model's data types live in the module that derives them; the seed
#: report's parts import its constants back. A new circle fails the test, and so does a listed one that is gone
#: (shorten the list).
KNOWN_CIRCLES = [
    {"mechsim.mechanisms.geneva.model", "mechsim.mechanisms.geneva.reduced"},
    {"mechsim.mechanisms.rolling.model", "mechsim.mechanisms.rolling.reduced"},
    {"mechsim.dynamics.derivation_cache", "mechsim.dynamics.model"},
    {"mechsim.benchmarks.seed_report", "mechsim.benchmarks.seed_report_plots", "mechsim.benchmarks.seed_report_text"},
]


def runtime_imports(tree: ast.AST) -> list:
    """The import nodes of a module, but those under `if TYPE_CHECKING:` (never executed)."""
    skip = set()
    for node in ast.walk(tree):
        if isinstance(node, ast.If) and "TYPE_CHECKING" in ast.unparse(node.test):
            skip.update(id(n) for stmt in node.body for n in ast.walk(stmt))
    return [n for n in ast.walk(tree) if isinstance(n, (ast.Import, ast.ImportFrom)) and id(n) not in skip]


def import_graph() -> dict[str, set[str]]:
    """module -> the product modules it imports (lazy imports included; `from package import module` is an import
    of the module, not of the package)."""
    modules = {".".join(module_name(p)): p for p in [*PRODUCT, ROOT / "__init__.py"]}

    def known(name: str) -> str | None:
        while name and name not in modules:
            name = name.rpartition(".")[0]
        return name or None
    graph = {}
    for name, path in modules.items():
        here = name.split(".")
        deps = set()
        for node in runtime_imports(ast.parse(path.read_text(encoding="utf-8"))):
            if isinstance(node, ast.Import):
                targets = [alias.name for alias in node.names]
            else:
                source = import_source(node, here, path.name == "__init__.py")
                subs = [f"{source}.{alias.name}" for alias in node.names]
                targets = [s for s in subs if s in modules]
                if len(targets) < len(subs):
                    targets.append(source)          # names that are not modules come from the package itself
            deps |= {m for m in map(known, targets) if m and m != name}
        graph[name] = deps
    return graph


def circles(graph: dict[str, set[str]]) -> list[set[str]]:
    """The strongly connected components of more than one module (Tarjan's algorithm, iterative)."""
    index, low, on_stack, stack, out = {}, {}, set(), [], []
    for root in graph:
        if root in index:
            continue
        index[root] = low[root] = len(index)
        stack.append(root)
        on_stack.add(root)
        work = [(root, iter(sorted(graph[root])))]
        while work:
            node, children = work[-1]
            child = next(children, None)
            if child is not None:
                if child not in index:
                    index[child] = low[child] = len(index)
                    stack.append(child)
                    on_stack.add(child)
                    work.append((child, iter(sorted(graph.get(child, ())))))
                elif child in on_stack:
                    low[node] = min(low[node], index[child])
                continue
            work.pop()
            if work:
                low[work[-1][0]] = min(low[work[-1][0]], low[node])
            if low[node] == index[node]:
                component = set()
                while True:
                    member = stack.pop()
                    on_stack.discard(member)
                    component.add(member)
                    if member == node:
                        break
                if len(component) > 1:
                    out.append(component)
    return out


def test_no_circles_between_modules():
    found = circles(import_graph())
    new = [sorted(c) for c in found if c not in KNOWN_CIRCLES]
    gone = [sorted(c) for c in KNOWN_CIRCLES if c not in found]
    assert not new, f"modules that import each other (directly or around a circle): {new}"
    assert not gone, f"no longer circles: remove them from KNOWN_CIRCLES: {gone}"


def test_the_circle_check_finds_a_circle_and_skips_type_checking_imports():
    graph = {"a": {"b"}, "b": {"c"}, "c": {"a"}, "d": {"a"}, "e": set()}
    assert circles(graph) == [{"a", "b", "c"}]
    tree = ast.parse("from typing import TYPE_CHECKING\nif TYPE_CHECKING:\n    import x\nimport y\n")
    assert [ast.unparse(n) for n in runtime_imports(tree)] == ["from typing import TYPE_CHECKING", "import y"]
