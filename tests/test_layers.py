"""The package's layers import one way (docs/design.md), counting every import, inside
functions too:

    _utils  <-  public tools  <-  descriptors  <-  registration  <-  batch, evaluation, cli

``_utils`` (and ``_version``) import nothing else of the package; the public tools
(``transforms``, ``open3d_interop``, ``io``, ``plotting``, ``datasets``) import only
``_utils``; a module may import its own layer or those below it, never one above, and
never the package's top (which only re-exports). No two modules import each other
through any chain, no module imports another module's private name (one with a leading
underscore: a private *module*'s public names are the package-internal API), and the
R-PointHop maths (``descriptors.pointhop``) imports no scikit-learn.
"""

from __future__ import annotations

import ast
from pathlib import Path

import pytest

PACKAGE = Path(__file__).resolve().parents[1] / "o3d_rpointhop"
TOP = "o3d_rpointhop"

#: Layer of every module, by the longest matching prefix.
LAYERS = {
    f"{TOP}._version": 0,
    f"{TOP}._utils": 0,
    f"{TOP}.transforms": 1,
    f"{TOP}.open3d_interop": 1,
    f"{TOP}.io": 1,
    f"{TOP}.poses": 1,
    f"{TOP}.plotting": 1,
    f"{TOP}.datasets": 1,
    f"{TOP}.descriptors": 2,
    f"{TOP}.registration": 3,
    f"{TOP}.batch": 4,
    f"{TOP}.viewer": 4,
    f"{TOP}.evaluation": 4,
    f"{TOP}.cli": 4,
}


def layer(module: str) -> int:
    """The layer of a module of the package (ValueError for one no layer names)."""
    matches = [p for p in LAYERS if module == p or module.startswith(p + ".")]
    return LAYERS[max(matches, key=len)]


def _exists(module: str) -> bool:
    parts = module.split(".")[1:]
    path = PACKAGE.joinpath(*parts)
    return path.with_suffix(".py").is_file() or (path / "__init__.py").is_file()


def module_name(path: Path) -> str:
    return ".".join(path.relative_to(PACKAGE.parent).with_suffix("").parts).removesuffix(
        ".__init__"
    )


def _type_only(tree: ast.AST) -> set[int]:
    """Ids of the import nodes under ``if TYPE_CHECKING:`` (read by type checkers only)."""
    ids = set()
    for node in ast.walk(tree):
        if isinstance(node, ast.If) and "TYPE_CHECKING" in ast.unparse(node.test):
            ids |= {id(n) for stmt in node.body for n in ast.walk(stmt)}
    return ids


def _from_target(node: ast.ImportFrom, package: str) -> str:
    """The absolute module a ``from ... import`` in ``package`` reads from."""
    if not node.level:
        return node.module or ""
    base = package.split(".")
    base = base[: len(base) - (node.level - 1)]
    return ".".join(base + ([node.module] if node.module else []))


def imports_of(source: str, name: str, is_package: bool, runtime_only: bool = False) -> set[str]:
    """Every module of the package that ``source`` (module ``name``) imports, at module
    level or inside any function or class; with ``runtime_only``, leaving out imports
    that only type checkers read."""
    package = name if is_package else name.rpartition(".")[0]
    found = set()
    tree = ast.parse(source)
    skipped = _type_only(tree) if runtime_only else set()
    for node in ast.walk(tree):
        if id(node) in skipped:
            continue
        if isinstance(node, ast.Import):
            found |= {a.name for a in node.names if a.name.split(".")[0] == TOP}
        elif isinstance(node, ast.ImportFrom):
            target = _from_target(node, package)
            if target.split(".")[0] != TOP:
                continue
            for alias in node.names:  # "from . import x" may name a submodule
                sub = f"{target}.{alias.name}"
                found.add(sub if _exists(sub) else target)
    return found


def private_imports(source: str, name: str, is_package: bool) -> list[str]:
    """Every private name (``_x``, not a dunder) that ``source`` imports from another
    module of the package; importing a private module is not counted."""
    package = name if is_package else name.rpartition(".")[0]
    found = []
    for node in ast.walk(ast.parse(source)):
        if not isinstance(node, ast.ImportFrom):
            continue
        target = _from_target(node, package)
        if target.split(".")[0] != TOP:
            continue
        for alias in node.names:
            private = alias.name.startswith("_") and not alias.name.startswith("__")
            if private and not _exists(f"{target}.{alias.name}"):
                found.append(f"{name} imports {alias.name} from {target}")
    return found


def import_graph(runtime_only: bool = False) -> dict[str, set[str]]:
    graph = {}
    for path in PACKAGE.rglob("*.py"):
        name = module_name(path)
        graph[name] = imports_of(path.read_text(), name, path.name == "__init__.py", runtime_only)
    return graph


def violations(graph: dict[str, set[str]]) -> list[str]:
    """Every import that runs against the layers, and every import of the top."""
    bad = []
    for module, targets in sorted(graph.items()):
        if module == TOP:
            continue
        for target in sorted(targets):
            if target == TOP:
                bad.append(f"{module} imports the package top (only re-exports live there)")
            elif layer(target) > layer(module):
                bad.append(f"{module} (layer {layer(module)}) imports {target} ({layer(target)})")
    return bad


def cycles(graph: dict[str, set[str]]) -> list[list[str]]:
    found, done = [], set()

    def visit(node, trail):
        for nxt in graph.get(node, ()):
            if nxt in trail:
                found.append(trail[trail.index(nxt) :] + [nxt])
            elif nxt not in done:
                visit(nxt, [*trail, nxt])
        done.add(node)

    for start in sorted(graph):
        if start not in done:
            visit(start, [start])
    return found


def test_every_module_has_a_layer():
    graph = import_graph()
    unplaced = []
    for module in graph:
        if module == TOP:
            continue
        try:
            layer(module)
        except ValueError:
            unplaced.append(module)
    assert unplaced == []


def test_imports_run_down_the_layers():
    assert violations(import_graph()) == []


def test_no_private_name_crosses_a_module():
    found = []
    for path in PACKAGE.rglob("*.py"):
        found += private_imports(path.read_text(), module_name(path), path.name == "__init__.py")
    assert found == []


def test_the_check_finds_private_names_not_private_modules():
    source = (
        "from ._consensus import _bits, consensus_sets\n"
        "from . import _ransac\n"
        "def f():\n    from ..pipeline import _check\n"
    )
    found = private_imports(source, f"{TOP}.registration.steps.consensus", is_package=False)
    steps = f"{TOP}.registration.steps"
    assert found == [
        f"{steps}.consensus imports _bits from {steps}._consensus",
        f"{steps}.consensus imports _check from {TOP}.registration.pipeline",
    ]


def private_modules_across_rooms(graph: dict[str, set[str]]) -> list[str]:
    """Every import of a private module (a path part with a leading underscore) of
    another room (top-level subpackage): a room's private modules are its own. The
    ground floor (``_utils``, ``_version``) is shared by every room."""
    bad = []
    for module, targets in sorted(graph.items()):
        room = module.split(".")[1] if "." in module else ""
        for target in sorted(targets):
            parts = target.split(".")[1:]
            if not parts or parts[0] in ("_utils", "_version") or parts[0] == room:
                continue
            if any(p.startswith("_") and not p.startswith("__") for p in parts[1:]):
                bad.append(f"{module} imports {target}, private to {parts[0]}")
    return bad


def test_no_private_module_crosses_a_room():
    assert private_modules_across_rooms(import_graph()) == []


def test_the_check_finds_private_modules_of_other_rooms():
    graph = {
        f"{TOP}.evaluation.sc2pcr": {f"{TOP}.registration.steps._consensus"},
        f"{TOP}.registration.steps.consensus": {f"{TOP}.registration.steps._consensus"},
        f"{TOP}.cli.register": {f"{TOP}._utils.threads", f"{TOP}.registration"},
    }
    assert private_modules_across_rooms(graph) == [
        f"{TOP}.evaluation.sc2pcr imports {TOP}.registration.steps._consensus, private to "
        "registration"
    ]


def test_no_import_cycles():
    # A type checker's import (under TYPE_CHECKING) runs against the layers like any
    # other, but never executes, so it cannot close a cycle.
    assert cycles(import_graph(runtime_only=True)) == []


def test_the_maths_has_no_scikit_learn():
    for path in (PACKAGE / "descriptors" / "pointhop").rglob("*.py"):
        tree = ast.parse(path.read_text())
        names = {a.name for n in ast.walk(tree) if isinstance(n, ast.Import) for a in n.names}
        names |= {n.module or "" for n in ast.walk(tree) if isinstance(n, ast.ImportFrom)}
        assert not any(n.split(".")[0] == "sklearn" for n in names), path


@pytest.mark.parametrize(
    "module, source, expected",
    [
        # An upward import inside a function is found like one at the top.
        (
            f"{TOP}.descriptors._fpfh",
            "def f():\n    from ..registration import settings\n",
            f"{TOP}.descriptors._fpfh (layer 2) imports {TOP}.registration.settings (3)",
        ),
        (
            f"{TOP}._utils.validation",
            "import o3d_rpointhop.batch\n",
            f"{TOP}._utils.validation (layer 0) imports {TOP}.batch (4)",
        ),
        (
            f"{TOP}.registration.context",
            "class C:\n    def m(self):\n        from .. import register\n",
            f"{TOP}.registration.context imports the package top (only re-exports live there)",
        ),
    ],
)
def test_the_check_finds_upward_imports_anywhere(module, source, expected):
    graph = {module: imports_of(source, module, is_package=False)}
    assert violations(graph) == [expected]


def test_the_check_finds_cycles():
    graph = {"a": {"b"}, "b": {"c"}, "c": {"a"}}
    assert cycles(graph) == [["a", "b", "c", "a"]]


def test_the_tests_mirror_the_package():
    """Every subpackage has its tests in the same place under ``tests/`` (a contributor
    finds a module's tests where the module is)."""
    tests = PACKAGE.parent / "tests"
    packages = [p.parent for p in PACKAGE.rglob("__init__.py") if p.parent != PACKAGE]
    missing = [
        str(p.relative_to(PACKAGE))
        for p in packages
        if not (tests / p.relative_to(PACKAGE)).is_dir()
    ]
    assert missing == [], f"subpackages without a tests folder: {missing}"
