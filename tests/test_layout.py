"""The code depends on itself in one direction: no import cycle between packages or between files,
lazy imports inside functions included (a lazy import hides a cycle from Python, not from a reader)."""

from __future__ import annotations

import ast
import functools
from collections.abc import Iterator
from pathlib import Path

import terrapref

ROOT = Path(terrapref.__file__).parent


@functools.cache
def _parsed(path: Path) -> ast.Module:
    """The module at ``path``, parsed once for all of this file's checks."""
    return ast.parse(path.read_text(), str(path))


@functools.cache
def _walked(tree: ast.AST) -> tuple[ast.AST, ...]:
    """Every node of ``tree`` (``ast.walk``'s order), listed once for all of this file's checks."""
    return tuple(ast.walk(tree))


def _package_imports() -> dict[str, set[str]]:
    """Top-level part (package or module) -> the other top-level parts it imports anywhere."""
    edges: dict[str, set[str]] = {}
    for path in ROOT.rglob("*.py"):
        part = path.relative_to(ROOT).parts[0].removesuffix(".py")
        for node in _walked(_parsed(path)):
            names = (
                [a.name for a in node.names]
                if isinstance(node, ast.Import)
                else [node.module or ""]
                if isinstance(node, ast.ImportFrom) and node.level == 0
                else []
            )
            for name in names:
                bits = name.split(".")
                if bits[0] == "terrapref" and len(bits) > 1 and bits[1] != part:
                    edges.setdefault(part, set()).add(bits[1])
    return edges


def _module_imports() -> dict[str, set[str]]:
    """Module (``terrapref.x.y``; a package is its ``__init__``) -> the terrapref modules it imports anywhere."""
    modules = {}
    for path in ROOT.rglob("*.py"):
        name = ".".join(("terrapref", *path.relative_to(ROOT).with_suffix("").parts)).removesuffix(".__init__")
        modules[name] = path
    edges: dict[str, set[str]] = {}
    for name, path in modules.items():
        for node in _walked(_parsed(path)):
            if isinstance(node, ast.ImportFrom) and node.level == 0 and (node.module or "").startswith("terrapref"):
                targets = [f"{node.module}.{a.name}" if f"{node.module}.{a.name}" in modules else node.module for a in node.names]
            elif isinstance(node, ast.Import):
                targets = [a.name for a in node.names]
            else:
                continue
            edges.setdefault(name, set()).update(t for t in targets if t in modules and t != name)
    return edges


def _cycle(edges: dict[str, set[str]]) -> list[str] | None:
    state: dict[str, int] = {}
    stack: list[str] = []

    def visit(node: str) -> list[str] | None:
        state[node] = 1
        stack.append(node)
        for nxt in sorted(edges.get(node, ())):
            if state.get(nxt) == 1:
                return stack[stack.index(nxt) :] + [nxt]
            if nxt not in state and (found := visit(nxt)):
                return found
        stack.pop()
        state[node] = 2
        return None

    for node in sorted(edges):
        if node not in state and (found := visit(node)):
            return found
    return None


def test_no_import_cycle_between_packages():
    edges = _package_imports()
    assert {"demos", "learning", "planner", "evaluation", "report"} <= set(edges), "the scan sees the packages"
    cycle = _cycle(edges)
    assert cycle is None, "import cycle: " + " -> ".join(cycle)


def test_no_import_cycle_between_files():
    edges = _module_imports()
    assert len(edges) > 50, "the scan sees the modules"
    cycle = _cycle(edges)
    assert cycle is None, "import cycle: " + " -> ".join(cycle)


def test_no_rule_package_imports_another():
    """What several rules read (the ground map, terrapref.groundmap) lives below the rules, never in one rule's package."""
    packages = {p.name for p in (ROOT / "rules").iterdir() if (p / "__init__.py").is_file()}

    def package(module: str) -> str | None:
        bits = module.split(".")
        return bits[2] if bits[:2] == ["terrapref", "rules"] and len(bits) > 2 and bits[2] in packages else None

    across = sorted(
        f"{a} -> {b}" for a, targets in _module_imports().items() for b in targets if package(a) and package(b) not in (None, package(a))
    )
    assert len(packages) >= 4, "the scan sees the rule packages"
    assert not across, "a rule package imports another: " + ", ".join(across)


def test_the_cycle_finder_finds_one():
    assert _cycle({"a": {"b"}, "b": {"c"}, "c": {"a"}}) == ["a", "b", "c", "a"]
    assert _cycle({"a": {"b"}, "b": {"c"}}) is None


# The package's layers, bottom first: a package may import only from layers below its own, so
# that the folder list reads as the data flow (scenario -> world -> vehicle and camera ->
# perception -> simulation -> features -> demonstrations -> datasets -> learning -> planner -> evaluation ->
# report) with the command line on top.
LAYERS = [
    {"errors"},
    {"extras"},
    {"yamlio", "fileio", "progress", "configargs", "registry", "records", "sums", "stops"},
    {"tensorfile", "terrain", "grid"},
    {"pngio", "scenario"},
    {"world"},
    {"vehicle", "plots"},
    {"camera"},
    {"perception"},
    {"sim"},
    {"features"},
    {"demos"},
    {"dataset"},
    {"learning"},
    {"groundmap"},
    {"rules"},
    {"planner"},
    {"baselines", "recipes"},
    {"interop"},
    {"evaluation", "teleop"},
    {"report", "filekinds"},
    {"cli", "runtime", "warm_up"},
]


def test_packages_import_only_from_the_layers_below_their_own():
    level = {name: i for i, layer in enumerate(LAYERS) for name in layer}
    edges = _package_imports()
    unplaced = (set(edges) | {t for ts in edges.values() for t in ts}) - set(level) - {"__init__", "__main__", "data"}
    assert not unplaced, f"packages missing from LAYERS: {sorted(unplaced)}"
    upward = sorted(f"{a} -> {b}" for a, targets in edges.items() for b in targets if b in level and level[b] >= level.get(a, len(LAYERS)))
    assert not upward, "imports against the layer order: " + ", ".join(upward)


def test_the_package_docstring_lists_the_layers_in_order():
    import re

    lines = [line.split(". ", 1)[1].split(" (")[0] for line in (terrapref.__doc__ or "").splitlines() if re.match(r"\d+\. ", line)]
    assert [set(line.split(", ")) for line in lines] == LAYERS


# The command line is one module per group of commands, each a few lines over library calls; a
# module past this many lines is a sign that logic has settled in the command line (docs/layout.md).
MAX_CLI_MODULE_LINES = 400


def test_no_command_line_module_is_longer_than_400_lines():
    modules = sorted((ROOT / "cli").glob("*.py"))
    assert len(modules) > 5, "the scan sees the cli package"
    long = {path.name: n for path in modules if (n := len(path.read_text().splitlines())) > MAX_CLI_MODULE_LINES}
    assert not long, f"cli modules over {MAX_CLI_MODULE_LINES} lines: {long}"


# Registered entry points ("module:attribute", resolved on first use, as Gymnasium's are) are
# imports too, made late. The one that points up the layers, and why:
LATE_ENTRY_POINTS = {
    ("planner", "baselines"): "the CNN baseline's file loader: loading any model file must not import torch unless it holds a CNN",
}


def test_entry_points_that_point_up_the_layers_are_the_named_ones():
    import re

    level = {name: i for i, layer in enumerate(LAYERS) for name in layer}
    found = set()
    for path in ROOT.rglob("*.py"):
        part = path.relative_to(ROOT).parts[0].removesuffix(".py")
        for node in _walked(_parsed(path)):
            if (
                isinstance(node, ast.Constant)
                and isinstance(node.value, str)
                and (m := re.fullmatch(r"terrapref\.(\w+)[\w.]*:\w+", node.value))
            ):
                if m.group(1) != part and level[m.group(1)] >= level[part]:
                    found.add((part, m.group(1)))
    assert found == set(LATE_ENTRY_POINTS)


# No function takes more than MAX_PARAMETERS (self and cls not counted): parameters that travel
# together are one record (a frozen dataclass). Numba's @njit kernels are exempt: they take
# arrays and scalars only.
MAX_PARAMETERS = 6


def _functions(tree: ast.AST) -> Iterator[tuple[str, ast.FunctionDef | ast.AsyncFunctionDef]]:
    """Every function in ``tree`` with its name (``Class.name`` for a method, ``outer.inner`` for a nested one)."""

    def visit(node: ast.AST, owner: str) -> Iterator[tuple[str, ast.FunctionDef | ast.AsyncFunctionDef]]:
        for child in ast.iter_child_nodes(node):
            if isinstance(child, (ast.FunctionDef, ast.AsyncFunctionDef)):
                yield f"{owner}{child.name}", child
                yield from visit(child, f"{owner}{child.name}.")
            elif isinstance(child, ast.ClassDef):
                yield from visit(child, f"{owner}{child.name}.")
            else:
                yield from visit(child, owner)

    return visit(tree, "")


@functools.cache
def _listed_functions(tree: ast.AST) -> tuple[tuple[str, ast.FunctionDef | ast.AsyncFunctionDef], ...]:
    """:func:`_functions` of ``tree``, listed once for both checks that read them."""
    return tuple(_functions(tree))


def _long_signatures(tree: ast.AST) -> set[str]:
    """``name`` (``Class.name`` for a method) of each function in ``tree`` that takes more than
    MAX_PARAMETERS parameters and is not an @njit kernel."""
    found = set()
    for name, f in _listed_functions(tree):
        a = f.args
        names = [x.arg for x in a.posonlyargs + a.args + a.kwonlyargs if x.arg not in ("self", "cls")]
        names += [x.arg for x in (a.vararg, a.kwarg) if x is not None]
        if len(names) > MAX_PARAMETERS and not any("njit" in ast.unparse(d) for d in f.decorator_list):
            found.add(name)
    return found


def test_no_function_takes_more_than_six_parameters():
    found = {name for path in ROOT.rglob("*.py") for name in _long_signatures(_parsed(path))}
    assert not found, f"more than {MAX_PARAMETERS} parameters: {sorted(found)}"


MAX_LINES = 60  # a function's lines, its decorators, signature and docstring included; compiled kernels too


def _long_functions(tree: ast.AST) -> set[str]:
    """``name`` (``Class.name`` for a method) of each function in ``tree`` longer than MAX_LINES."""
    return {
        name for name, f in _listed_functions(tree) if f.end_lineno - min([f.lineno, *(d.lineno for d in f.decorator_list)]) + 1 > MAX_LINES
    }


def test_no_function_is_longer_than_60_lines():
    """Split a longer one by what its parts compute (a kernel too: into kernels that inline)."""
    found = {f"{path.relative_to(ROOT)}:{name}" for path in ROOT.rglob("*.py") for name in _long_functions(_parsed(path))}
    assert not found, f"more than {MAX_LINES} lines: {sorted(found)}"


def test_the_length_check_counts_lines_as_written():
    def lines(indent: str, n: int) -> str:
        return "".join(f"{indent}x{i} = {i}\n" for i in range(n))

    code = (
        'def fits():\n    """doc"""\n'
        + lines("    ", 58)  # 60 lines
        + "@njit(cache=True)\ndef kernel():\n"
        + lines("    ", 59)  # 61 with its decorator
        + "class A:\n    def long(self):\n"
        + lines("        ", 60)  # 61
    )
    assert _long_functions(ast.parse(code)) == {"kernel", "A.long"}


def test_the_signature_check_counts_parameters_as_written():
    code = """
def six(a, b, c, d, e, f): ...
def seven(a, b, c, d, e, f, *, g=0): ...
def rest(a, b, c, d, e, f, *args): ...
@njit(cache=True)
def kernel(a, b, c, d, e, f, g): ...
class Thing:
    def __init__(self, a, b, c, d, e, f): ...
    @classmethod
    def make(cls, a, b, c, d, e, f, g): ...
"""
    assert _long_signatures(ast.parse(code)) == {"seven", "rest", "Thing.make"}


# A name that starts with one underscore is its module's own: no other module of the package
# imports it (``from terrapref.a import _x``) or reaches for it on a module it imported
# (``a._x``). What two modules share is public in one of them. The scan covers src/terrapref/
# only: a test may use the private names of the module it tests.


def _private_uses(tree: ast.AST, module: str, modules: set[str]) -> set[str]:
    """``used._name`` for each private name of another terrapref module that the code in ``tree``
    (the module ``module``; ``modules``: every module of the package) imports or reads off a
    module it imported. Dunder names (``__version__``) are not private."""

    def private(name: str) -> bool:
        return name.startswith("_") and not name.endswith("__")

    found, bound = set(), {}  # bound: a name in the file -> the terrapref module it is
    for node in _walked(tree):
        if isinstance(node, ast.ImportFrom):
            base = node.module or ""
            if node.level:  # relative: resolved against the module's own package
                base = ".".join([*module.split(".")[: -node.level], *([base] if base else [])])
            if not base.startswith("terrapref"):
                continue
            for alias in node.names:
                if f"{base}.{alias.name}" in modules:
                    bound[alias.asname or alias.name] = f"{base}.{alias.name}"
                elif private(alias.name) and base != module:
                    found.add(f"{base}.{alias.name}")
        elif isinstance(node, ast.Import):
            for alias in node.names:
                if alias.name.startswith("terrapref"):  # ``import terrapref.a.b`` binds terrapref; ``... as m``, the module
                    bound[alias.asname or "terrapref"] = alias.name if alias.asname else "terrapref"
    for node in _walked(tree):
        if isinstance(node, ast.Attribute) and private(node.attr):
            first, *rest = ast.unparse(node.value).split(".")
            target = ".".join([bound[first], *rest]) if first in bound else None  # ``pkg.b._x``: pkg's module, then b
            if target in modules and target != module:
                found.add(f"{target}.{node.attr}")
    return found


def _modules() -> dict[str, Path]:
    """Module name (``terrapref.x.y``; a package is its ``__init__``) -> its file."""
    return {
        ".".join(("terrapref", *path.relative_to(ROOT).with_suffix("").parts)).removesuffix(".__init__"): path
        for path in ROOT.rglob("*.py")
    }


def test_no_module_uses_a_private_name_of_another():
    modules = _modules()
    assert len(modules) > 50, "the scan sees the modules"
    names = set(modules)
    found = {f"{name}: {used}" for name, path in modules.items() for used in _private_uses(_parsed(path), name, names)}
    assert not found, "private names used outside their module (make them public where they belong): " + ", ".join(sorted(found))


def test_the_private_name_check_finds_each_way_of_reaching_one():
    modules = {"terrapref", "terrapref.a", "terrapref.a.b", "terrapref.c"}
    code = """
from terrapref.a.b import _hidden, shown, __version__
from terrapref.a import b
from terrapref import a as pkg
from . import b as sibling
from .b import _relative
import terrapref.c
import terrapref.c as c_alias
b._through_module
pkg._through_package
pkg.b._through_package_then_module
sibling._through_relative
terrapref.c._through_dotted
c_alias._through_alias
b.shown._attribute_of_a_value
self._own
"""
    assert _private_uses(ast.parse(code), "terrapref.a.x", modules) == {
        "terrapref.a.b._hidden",
        "terrapref.a.b._through_module",
        "terrapref.a._through_package",
        "terrapref.a.b._through_package_then_module",
        "terrapref.a.b._through_relative",
        "terrapref.a.b._relative",
        "terrapref.c._through_dotted",
        "terrapref.c._through_alias",
    }
    assert _private_uses(ast.parse("from terrapref.a.x import _mine\n"), "terrapref.a.x", modules) == set()


def test_the_tests_are_in_folders_that_mirror_the_packages():
    """A package's tests are in tests/<package>/; at the top, only what spans the whole project
    (layout, docs, fuzzing the file formats, the small shared modules) and the tests' own helpers."""
    tests = Path(__file__).resolve().parent
    folders = {p.name for p in tests.iterdir() if p.is_dir() and p.name not in ("data", "__pycache__")}
    packages = {p.name for p in ROOT.iterdir() if (p / "__init__.py").is_file()}
    assert folders <= packages, sorted(folders - packages)
    for folder in folders:
        assert list((tests / folder).glob("test_*.py")), folder
    top = {p.stem for p in tests.glob("test_*.py")}
    modules = {p.stem for p in ROOT.glob("*.py")}
    assert all(name.removeprefix("test_") in modules | {"layout", "docs", "fuzz"} for name in top), sorted(top)
