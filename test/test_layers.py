"""The package's layers (README, Layout): each layer imports only layers below it, the
atlas and the search know nothing of cables, and no modules import each other in a cycle."""

import ast
import subprocess
import sys

from conftest import PACKAGE
# lower number = lower layer; a module may import its own layer and those below
LAYER = {"cdh_planner": 0, "aot": 0, "errors": 0, "fields": 0, "files": 0, "ports": 0, "progress": 0, "status": 0, "model": 1,
         "wrench": 2, "scene": 2, "accuracy": 2, "accuracy_kernel": 0, "accuracy_aot": 0, "kernel_linalg": 0, "parallel": 0,
         "compiled_json": 0,
         "manifold": 3, "atlas": 3, "search": 4, "trajectory": 4, "settings": 5,
         "planner": 6, "pipeline": 6, "parsing": 7, "pictures": 7, "recording": 7, "studies": 7, "sim": 7,
         "ros": 8, "commands": 9, "cli": 10, "cli_reference": 10}
CABLE_FREE = {"atlas", "search"}  # they see F, F_x, bounds and costs only
GENERIC = {"cdh_planner", "errors", "status", "atlas", "search"}


def _imports():
    """{module: set of cdh_planner modules it imports (anywhere in its body)}."""
    out = {}
    files = sorted(PACKAGE.rglob("*.py"))
    modules = {".".join(f.relative_to(PACKAGE.parent).with_suffix("").parts).removesuffix(".__init__")
               for f in files}
    for f in files:
        parts = f.relative_to(PACKAGE.parent).with_suffix("").parts
        module = ".".join(parts[:-1] if parts[-1] == "__init__" else parts)
        package = module if f.name == "__init__.py" else module.rsplit(".", 1)[0]
        found = set()
        for node in ast.walk(ast.parse(f.read_text())):
            if isinstance(node, ast.ImportFrom):
                if node.level:
                    base = package.split(".")[:len(package.split(".")) - node.level + 1]
                    target = ".".join(base + ([node.module] if node.module else []))
                else:
                    target = node.module or ""
                # ``from package import module`` depends on the module (and the package's
                # __init__, which stays empty where a module sits below its package's layer)
                names = [f"{target}.{a.name}" for a in node.names]
                submodules = [n for n in names if n in modules]
                found |= {t for t in submodules or [target] if t.startswith("cdh_planner")}
            elif isinstance(node, ast.Import):
                found |= {a.name for a in node.names if a.name.startswith("cdh_planner")}
        out[module] = found
    return {m: {t for t in ts if t in modules and t != m} for m, ts in out.items()}


def _layer(module):
    """The LAYER key of a module: its top-level package's or module's name."""
    parts = module.split(".")
    return parts[min(1, len(parts) - 1)]


def test_every_module_imports_only_its_layer_and_those_below():
    bad = [(m, t) for m, ts in _imports().items() for t in ts
           if LAYER[_layer(t)] > LAYER[_layer(m)]]
    assert not bad, f"imports from a higher layer: {bad}"


def test_wrench_is_reached_only_through_its_entry():
    """``cdh_planner.wrench``'s modules are its own: other packages import the package."""
    bad = [(m, t) for m, ts in _imports().items() if _layer(m) != "wrench"
           for t in ts if t.startswith("cdh_planner.wrench.")]
    assert not bad, f"imports of wrench's internals: {bad}"


def test_atlas_and_search_know_nothing_of_cables():
    bad = [(m, t) for m, ts in _imports().items() if _layer(m) in CABLE_FREE
           for t in ts if _layer(t) not in GENERIC]
    assert not bad, bad


def _assert_acyclic(graph, what):
    """Depth-first search over ``graph`` ({node: targets}); the first cycle found fails."""
    state = {}

    def visit(node, stack):
        state[node] = "open"
        for t in sorted(graph.get(node, ())):
            if state.get(t) == "open":
                raise AssertionError(f"{what} cycle: {' -> '.join(stack + [node, t])}")
            if t not in state:
                visit(t, stack + [node])
        state[node] = "done"

    for node in sorted(graph):
        if node not in state:
            visit(node, [])


def test_no_import_cycles():
    _assert_acyclic(_imports(), "import")


def test_no_package_level_cycles():
    """Packages as units: no two of them import each other, through any chain."""
    graph = {}
    for m, ts in _imports().items():
        graph.setdefault(_layer(m), set()).update(_layer(t) for t in ts if _layer(t) != _layer(m))
    _assert_acyclic(graph, "package")


RCLPY_FREE = ("cdh_planner.ros.core", "cdh_planner.ros.msgs")   # the node's logic, conversions


def _rclpy_free_modules():
    return sorted(m for m in _imports() if m.startswith(RCLPY_FREE))


def test_the_node_logic_and_the_conversions_import_no_rclpy():
    """Nothing under ros/core/ or ros/msgs/ imports rclpy, lazily neither; importing all of
    them in a fresh interpreter loads no rclpy module (nor does anything they import)."""
    bad = []
    for module in _rclpy_free_modules():
        path = PACKAGE.parent.joinpath(*module.split(".")).with_suffix(".py")
        if not path.exists():
            path = path.with_suffix("") / "__init__.py"
        for node in ast.walk(ast.parse(path.read_text())):
            names = ([a.name for a in node.names] if isinstance(node, ast.Import) else
                     [node.module or ""] if isinstance(node, ast.ImportFrom) and not node.level else [])
            bad += [(module, n) for n in names if n == "rclpy" or n.startswith("rclpy.")]
    assert not bad, bad
    code = ("import importlib, sys\n"
            f"for m in {_rclpy_free_modules()!r}: importlib.import_module(m)\n"
            "print(sorted(k for k in sys.modules if k == 'rclpy' or k.startswith('rclpy.')))")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=120)
    assert out.returncode == 0, out.stderr
    assert out.stdout.strip() == "[]", out.stdout
