"""The import graph runs one way (issue 32).

Layers, lowest first: ``assets_usd`` -> ``kernels`` -> ``sim`` -> ``policies`` -> ``dynpush`` (the CLI). A module
may import its own layer or a lower one, never a higher one. ``runtime`` stands apart: besides the standard library
it depends on numpy, onnxruntime, yaml and the motion-capture client only, never on kernels, sim or policies, nor on
torch, warp or newton; the layers may take pure layout constants from its light modules
(``kernels/push/observations.py`` reads ``runtime/observation.py``).
No module imports a private (leading underscore) name from another module, and the imports that run form no cycle:
neither those at module level nor those inside functions (a deferred import that closes a circle is a module-level
one waiting for a caller; the shared code belongs in the lower module). Imports under ``if TYPE_CHECKING:`` never
run and are left out of the cycle check: annotations may name a higher module's types. The graph is read with
``ast`` from the source, so nothing is imported to check it.
"""

from __future__ import annotations

import ast
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent

# Installed package name -> source folder (pyproject's package-dir).
PACKAGES = {
    "dynpush.assets_usd": "assets_usd",
    "dynpush.kernels": "kernels",
    "dynpush.sim": "sim",
    "dynpush.policies": "policies",
    "dynpush.runtime": "runtime",
    "dynpush": "dynpush",
}
LAYER = {
    "dynpush.assets_usd": 0,
    "dynpush.kernels": 1,
    "dynpush.sim": 2,
    "dynpush.policies": 3,
    "dynpush": 4,
}
# Standard-library-only modules at the root that every layer, the runtime included, may import.
BASE = {"dynpush", "dynpush.errors", "dynpush.shipped"}
# What the runtime may import besides itself and BASE: the joint-name constants of the assets package (its
# ``__init__`` is standard library only; the USD generator next to it is not).
RUNTIME_MAY_IMPORT = BASE | {"dynpush.assets_usd"}
HEAVY = ("torch", "warp", "newton", "mujoco", "mujoco_warp", "rsl_rl", "tensordict", "pxr")
# The third-party packages the runtime may import (an allow-list: what a robot's computer installs for it): arrays,
# the ONNX session, its YAML config and the motion-capture client (imported only when that source is configured).
RUNTIME_THIRD_PARTY = {"numpy", "onnxruntime", "yaml", "motioncapture"}

# Known exceptions, each with the issue that removes it: (importer, imported). Empty when the layering holds.
ALLOWED_UPWARD: set[tuple[str, str]] = set()
ALLOWED_CYCLES: list[set[str]] = []


def _modules() -> dict[str, Path]:
    out: dict[str, Path] = {}
    for package, folder in PACKAGES.items():
        base = ROOT / folder
        for path in sorted(base.rglob("*.py")):
            if package == "dynpush" and path.parent != ROOT / "dynpush":
                continue
            # A subfolder is a subpackage (``kernels/push/``, ``kernels/locomotion/``).
            parts = path.relative_to(base).with_suffix("").parts
            if parts[-1] == "__init__":
                parts = parts[:-1]
            out[".".join((package, *parts))] = path
    out["dynpush.shipped"] = ROOT / "dynpush" / "shipped" / "__init__.py"
    return out


MODULES = _modules()


def _package_of(module: str) -> str:
    """The layer package a module belongs to (longest matching prefix)."""
    best = ""
    for package in PACKAGES:
        if (module == package or module.startswith(package + ".")) and len(package) > len(best):
            best = package
    return best


def _resolve(module: str, node: ast.ImportFrom) -> str:
    if node.level == 0:
        return node.module or ""
    is_package = MODULES[module].stem == "__init__"
    parts = module.split(".")
    base = parts if is_package else parts[:-1]
    if node.level > 1:
        base = base[: len(base) - (node.level - 1)]
    return ".".join(base + ([node.module] if node.module else []))


def _imports(module: str, top_level_only: bool, type_checking: bool = True) -> list[tuple[str, list[str], int]]:
    """(imported module, imported names, line) for every import in ``module``.

    ``top_level_only`` keeps the imports that run when the module is imported (module body, including ``if``
    and ``try`` blocks, but not function bodies or ``TYPE_CHECKING`` blocks). ``type_checking=False`` leaves out
    the imports of ``TYPE_CHECKING`` blocks, which never run.
    """
    tree = ast.parse(MODULES[module].read_text(), filename=str(MODULES[module]))
    found: list[tuple[str, list[str], int]] = []

    def visit(nodes, deferred: bool) -> None:
        for node in nodes:
            if isinstance(node, ast.Import):
                if not (top_level_only and deferred):
                    found.extend((alias.name, [], node.lineno) for alias in node.names)
            elif isinstance(node, ast.ImportFrom):
                if not (top_level_only and deferred):
                    target = _resolve(module, node)
                    names = [alias.name for alias in node.names]
                    # `from pkg import submodule` imports the submodule.
                    subs = [f"{target}.{n}" for n in names if f"{target}.{n}" in MODULES]
                    if subs:
                        found.extend((s, [], node.lineno) for s in subs)
                        rest = [n for n in names if f"{target}.{n}" not in MODULES]
                        if rest:
                            found.append((target, rest, node.lineno))
                    else:
                        found.append((target, names, node.lineno))
            elif isinstance(node, (ast.FunctionDef, ast.AsyncFunctionDef, ast.Lambda)):
                visit(ast.iter_child_nodes(node), True)
            elif isinstance(node, ast.If) and "TYPE_CHECKING" in ast.unparse(node.test):
                visit(node.orelse, deferred)
                if type_checking:
                    visit(node.body, True)
            else:
                visit(ast.iter_child_nodes(node), deferred)

    visit(tree.body, False)
    return found


def _internal(target: str) -> str | None:
    """The module of this repository that ``target`` names (a package resolves to its ``__init__``)."""
    return target if target in MODULES else None


def test_the_modules_are_found():
    assert "dynpush.cli" in MODULES and "dynpush.runtime.app" in MODULES and "dynpush.kernels.push.views" in MODULES
    assert "dynpush.kernels.locomotion.views" in MODULES and "dynpush.kernels.frames" in MODULES


def test_base_modules_import_only_each_other():
    bad = []
    for module in BASE:
        for target, _, line in _imports(module, top_level_only=False):
            if target.startswith("dynpush") and target not in BASE or target.split(".")[0] in HEAVY:
                bad.append(f"{module}:{line} imports {target}")
    assert not bad, "\n".join(bad)


def test_runtime_stands_apart():
    bad = []
    for module in MODULES:
        if _package_of(module) != "dynpush.runtime":
            continue
        for target, _, line in _imports(module, top_level_only=False):
            root = target.split(".")[0]
            if target.startswith("dynpush"):
                if _package_of(target) != "dynpush.runtime" and target not in RUNTIME_MAY_IMPORT:
                    bad.append(f"{module}:{line} imports {target}")
            elif root not in sys.stdlib_module_names and root not in RUNTIME_THIRD_PARTY:
                bad.append(f"{module}:{line} imports {target}")
    assert not bad, (f"runtime/ may import the standard library, {sorted(RUNTIME_THIRD_PARTY)} and"
                     f" {sorted(RUNTIME_MAY_IMPORT)} only:\n" + "\n".join(bad))


def test_only_the_cli_imports_the_command_modules():
    """Each package's ``commands.py`` (its argument parsers) belongs to the CLI layer: only ``dynpush.cli`` imports
    them, so no library module depends on a parser."""
    bad = [f"{module}:{line} imports {target}" for module in MODULES if module != "dynpush.cli"
           for target, _, line in _imports(module, top_level_only=False)
           if target.startswith("dynpush") and target.rsplit(".", 1)[-1] == "commands"]
    assert not bad, "\n".join(bad)


def _light_runtime_modules() -> set[str]:
    """Runtime modules that import only the standard library, numpy and other such modules at module level."""
    light: set[str] = set()
    runtime = [m for m in MODULES if _package_of(m) == "dynpush.runtime"]
    changed = True
    while changed:
        changed = False
        for module in runtime:
            if module in light:
                continue
            ok = True
            for target, _, _ in _imports(module, top_level_only=True):
                root = target.split(".")[0]
                if target.startswith("dynpush"):
                    ok = ok and (target in light or target in RUNTIME_MAY_IMPORT)
                else:
                    ok = ok and (root in sys.stdlib_module_names or root == "numpy")
            if ok:
                light.add(module)
                changed = True
    return light


def test_kernels_take_only_light_runtime_modules():
    """The kernels may read layout constants from the runtime, but only from its numpy-only modules."""
    light = _light_runtime_modules()
    bad = []
    for module in MODULES:
        if _package_of(module) != "dynpush.kernels":
            continue
        for target, _, line in _imports(module, top_level_only=False):
            if _package_of(target) == "dynpush.runtime" and target not in light:
                bad.append(f"{module}:{line} imports {target}")
    assert not bad, "\n".join(bad)


def test_no_upward_import():
    bad = []
    for module in MODULES:
        package = _package_of(module)
        if package not in LAYER:
            continue
        for target, _, line in _imports(module, top_level_only=False):
            if not target.startswith("dynpush") or target in BASE:
                continue
            imported = _package_of(target)
            if imported in LAYER and LAYER[imported] > LAYER[package] and (module, target) not in ALLOWED_UPWARD:
                bad.append(f"{module}:{line} imports {target}")
    assert not bad, "imports must run assets_usd -> kernels -> sim -> policies -> cli:\n" + "\n".join(bad)


def test_no_private_name_across_modules():
    bad = []
    for module in MODULES:
        for target, names, line in _imports(module, top_level_only=False):
            if not target.startswith("dynpush") or target == module:
                continue
            private = [n for n in names if n.startswith("_") and not n.startswith("__")]
            if private:
                bad.append(f"{module}:{line} imports {', '.join(private)} from {target}")
    assert not bad, "private names stay in their module:\n" + "\n".join(bad)


def _import_graph(top_level_only: bool) -> dict[str, dict[str, int]]:
    """Module -> {imported module of this repository: line of the first such import}, for the imports that run:
    at module level, and inside functions too unless ``top_level_only``."""
    graph: dict[str, dict[str, int]] = {m: {} for m in MODULES}
    for module in MODULES:
        for target, _, line in _imports(module, top_level_only, type_checking=False):
            # Importing a.b.c runs a/__init__ and a/b/__init__ as well.
            parts = target.split(".")
            for i in range(1, len(parts) + 1):
                name = _internal(".".join(parts[:i]))
                if name is not None and name != module:
                    graph[module].setdefault(name, line)
    return graph


def _cycles(graph: dict[str, dict[str, int]]) -> list[set[str]]:
    """The strongly connected components of more than one module (Tarjan)."""
    index: dict[str, int] = {}
    low: dict[str, int] = {}
    stack: list[str] = []
    on_stack: set[str] = set()
    cycles: list[set[str]] = []
    counter = [0]

    def strong(v: str) -> None:
        index[v] = low[v] = counter[0]
        counter[0] += 1
        stack.append(v)
        on_stack.add(v)
        for w in sorted(graph[v]):
            if w not in index:
                strong(w)
                low[v] = min(low[v], low[w])
            elif w in on_stack:
                low[v] = min(low[v], index[w])
        if low[v] == index[v]:
            component = set()
            while True:
                w = stack.pop()
                on_stack.discard(w)
                component.add(w)
                if w == v:
                    break
            if len(component) > 1:
                cycles.append(component)

    for v in sorted(graph):
        if v not in index:
            strong(v)
    return [c for c in cycles if c not in ALLOWED_CYCLES]


def _describe(graph: dict[str, dict[str, int]], cycles: list[set[str]]) -> str:
    """Each cycle's modules and the imports (module:line -> module) that join them."""
    return "\n".join(" <-> ".join(sorted(c)) + "".join(
        f"\n    {m}:{graph[m][t]} -> {t}" for m in sorted(c) for t in sorted(graph[m]) if t in c) for c in cycles)


def test_no_import_cycle():
    graph = _import_graph(top_level_only=True)
    cycles = _cycles(graph)
    assert not cycles, "module-level import cycles:\n" + _describe(graph, cycles)


def test_no_import_cycle_through_imports_inside_functions():
    graph = _import_graph(top_level_only=False)
    cycles = _cycles(graph)
    assert not cycles, ("import cycles (imports inside functions included); move the shared code to the lower module:\n"
                        + _describe(graph, cycles))
