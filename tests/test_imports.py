"""The import graph of the product's Python packages: every module imports, no module imports itself back
through others (cycles), and imports inside functions are only for heavy or environment-bound
dependencies (Blender's modules, packages one code path needs, or a module tried with a fallback when it
is missing), each with a comment saying so."""

from __future__ import annotations

import ast
import importlib
from pathlib import Path

import pytest

REPO_ROOT = Path(__file__).resolve().parent.parent
#: package folder -> the module name of that folder
PACKAGES = {REPO_ROOT / "addon": "addon", REPO_ROOT / "service": "service", REPO_ROOT / "tools": "tools",
            REPO_ROOT / "blend_scenes": "blend_scenes",
            REPO_ROOT / "sim_core" / "python" / "sim_core": "sim_core"}
#: What may be imported inside a function (besides the native core inside the add-on: sim_core and our
#: modules that import it, which load on first use rather than when Blender starts the add-on): Blender's
#: modules (only inside Blender or the bpy module, some only with a GPU context), and heavy or optional
#: packages only one code path needs.
LAZY_ALLOWED = {"bpy", "bmesh", "mathutils", "addon_utils", "blf", "gpu", "gpu_extras", "matplotlib",
                "distributed", "dask", "uvicorn", "flip_evaluator"}


def _modules() -> dict[str, Path]:
    found = {}
    for folder, name in PACKAGES.items():
        for path in folder.rglob("*.py"):
            parts = list(path.relative_to(folder).with_suffix("").parts)
            if parts[-1] == "__init__":
                parts.pop()
            if "build" in parts or "__pycache__" in parts:
                continue
            found[".".join([name, *parts])] = path
    return found


MODULES = _modules()


def _resolve(module: str, path: Path, node: ast.Import | ast.ImportFrom) -> list[str]:
    """Internal modules an import statement loads (names imported from a package count as its
    submodules when such a module exists, else as the package itself)."""
    if isinstance(node, ast.Import):
        targets = [a.name for a in node.names]
    else:
        if node.level:
            package = module.split(".") if path.name == "__init__.py" else module.split(".")[:-1]
            base = ".".join(package[:len(package) - node.level + 1] + ([node.module] if node.module else []))
        else:
            base = node.module or ""
        targets = [f"{base}.{a.name}" if f"{base}.{a.name}" in MODULES or _compiled(f"{base}.{a.name}")
                   else base for a in node.names]
    out = []
    for target in targets:
        parts = target.split(".")
        while parts and ".".join(parts) not in MODULES:
            parts.pop()
        if parts and not _compiled(target):
            out.append(".".join(parts))
    return out


def _compiled(name: str) -> bool:
    """A native extension module (sim_core._core): a leaf, it imports nothing of ours."""
    return name == "sim_core._core"


def _imports(module: str) -> list[tuple[ast.Import | ast.ImportFrom, bool]]:
    """(import node, inside a function) for every import of a module."""
    return [(node, inside) for node, inside, _ in _import_sites(module)]


def _import_sites(module: str) -> list[tuple[ast.Import | ast.ImportFrom, bool, bool]]:
    """(import node, inside a function, inside a ``try`` that handles ImportError) for every import."""
    tree = ast.parse(MODULES[module].read_text(encoding="utf-8"))
    found: list[tuple[ast.Import | ast.ImportFrom, bool, bool]] = []

    def handles_import_error(node: ast.AST) -> bool:
        return isinstance(node, ast.Try) and any(
            isinstance(h.type, ast.Name) and h.type.id in ("ImportError", "ModuleNotFoundError")
            for h in node.handlers)

    def walk(node: ast.AST, in_function: bool, guarded: bool) -> None:
        for child in ast.iter_child_nodes(node):
            if isinstance(child, ast.Import | ast.ImportFrom):
                found.append((child, in_function, guarded))
            walk(child, in_function or isinstance(child, ast.FunctionDef | ast.AsyncFunctionDef),
                 guarded or handles_import_error(child))

    walk(tree, False, False)
    return found


def _graph() -> dict[str, set[str]]:
    return {m: {t for node, _ in _imports(m) for t in _resolve(m, MODULES[m], node) if t != m}
            for m in MODULES}


def _cycles(graph: dict[str, set[str]]) -> list[list[str]]:
    """Strongly connected components with more than one module (Tarjan)."""
    index: dict[str, int] = {}
    low: dict[str, int] = {}
    stack: list[str] = []
    on_stack: set[str] = set()
    out: list[list[str]] = []

    def visit(v: str) -> None:
        index[v] = low[v] = len(index)
        stack.append(v)
        on_stack.add(v)
        for w in sorted(graph[v]):
            if w not in index:
                visit(w)
                low[v] = min(low[v], low[w])
            elif w in on_stack:
                low[v] = min(low[v], index[w])
        if low[v] == index[v]:
            comp = []
            while True:
                w = stack.pop()
                on_stack.discard(w)
                comp.append(w)
                if w == v:
                    break
            if len(comp) > 1:
                out.append(sorted(comp))

    for v in sorted(graph):
        if v not in index:
            visit(v)
    return out


def test_the_checker_finds_a_cycle() -> None:
    assert _cycles({"a": {"b"}, "b": {"c"}, "c": {"a"}, "d": {"a"}}) == [["a", "b", "c"]]
    assert _cycles({"a": {"b"}, "b": set()}) == []


def test_no_import_cycles() -> None:
    """Function-level imports count too: a cycle hidden in a function body is still a cycle."""
    graph = _graph()
    assert "sim_core.loaders.gltf" in graph and "sim_core.image" in graph["sim_core.loaders.gltf"]
    assert _cycles(graph) == []


def _bpy_bound(graph_top: dict[str, set[str]]) -> set[str]:
    """Modules that import a Blender module or a heavy package (LAZY_ALLOWED) at their top level,
    directly or through ours: importing them lazily is importing that lazily."""
    return _reaching(graph_top, {m for m in MODULES for node, inside in _imports(m) if not inside
                                 and any(n.split(".")[0] in LAZY_ALLOWED for n in _names(node))})


def _core_bound(graph_top: dict[str, set[str]]) -> set[str]:
    """sim_core's modules and ours that import one at their top level, directly or through ours: each
    loads the native core."""
    return _reaching(graph_top, {m for m in MODULES if m == "sim_core" or m.startswith("sim_core.")})


def _reaching(graph_top: dict[str, set[str]], bound: set[str]) -> set[str]:
    """``bound`` and every module whose top-level imports reach it."""
    bound = set(bound)
    changed = True
    while changed:
        grown = {m for m, targets in graph_top.items() if targets & bound} - bound
        bound |= grown
        changed = bool(grown)
    return bound


def _names(node: ast.Import | ast.ImportFrom) -> list[str]:
    """The third-party (or standard) modules an import names; ours are left out."""
    names = [a.name for a in node.names] if isinstance(node, ast.Import) else (
        [node.module or ""] if not node.level else [])
    return [n for n in names if n.split(".")[0] not in set(PACKAGES.values())]


def test_imports_inside_functions_are_only_the_lazy_kind_and_say_why() -> None:
    graph_top = {m: {t for node, inside in _imports(m) if not inside for t in _resolve(m, MODULES[m], node)}
                 for m in MODULES}
    bound, core = _bpy_bound(graph_top), _core_bound(graph_top)
    assert "service.evaluation" in core and "service.store" not in core
    offenders = []
    for m, path in MODULES.items():
        lines = path.read_text(encoding="utf-8").splitlines()
        for node, inside, guarded in _import_sites(m):
            if not inside:
                continue
            external = [n.split(".")[0] for n in _names(node)]
            internal = _resolve(m, path, node)
            in_addon = m.startswith("addon.")
            core_in_addon = in_addon and not external and all(t in core for t in internal or ["-"])
            heavy = all(n in LAZY_ALLOWED for n in external) and all(t in bound for t in internal)
            allowed = guarded or core_in_addon or (heavy and bool(external or internal))
            above = lines[max(0, node.lineno - 4):node.lineno]
            commented = any("#" in line and "lazy" in line.lower() for line in above)
            if not (allowed and commented):
                offenders.append(f"{path.relative_to(REPO_ROOT)}:{node.lineno}")
    assert offenders == []


@pytest.mark.parametrize("module", sorted(MODULES))
def test_every_module_imports(module: str) -> None:
    if any(module.startswith(p) for p in ("addon.", "blend_scenes.")) or module in ("addon", "blend_scenes"):
        pytest.importorskip("bpy")
    importlib.import_module(module)
