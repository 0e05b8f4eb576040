"""Layers point down: a walk of defgg_ros's import graph (every import statement, also those inside
functions) fails on an import cycle, between packages or between modules, and on a core package
importing rclpy or a layer above the cores (the ROS plumbing, nodes, bringup, sessions, the demo).

Cores: model, grasping, perception, control, sim, data, planning (the tabletop planner that combines
grasping, control, perception and model). Above them: train, evaluation (offline),
ros (rclpy helpers), nodes (thin adapters), bringup, sessions, demo. Below them: the root modules
(constants, errors, stiffness, grip_force, rotations, atomic).
"""
import ast
from pathlib import Path

import pytest

pytestmark = pytest.mark.unit

PACKAGE_DIR = Path(__file__).resolve().parents[2] / "defgg_ros"
CORES = ("model", "grasping", "perception", "control", "sim", "data", "planning")
ABOVE_CORES = ("ros", "nodes", "bringup", "sessions", "demo", "train", "evaluation")
ROS_MODULES = ("rclpy", "rosidl_runtime_py", "rosbag2_py")


def _module_name(path: Path) -> str:
    parts = list(path.relative_to(PACKAGE_DIR.parent).with_suffix("").parts)
    return ".".join(parts[:-1] if parts[-1] == "__init__" else parts)


MODULES = {_module_name(p): p for p in PACKAGE_DIR.rglob("*.py")}


def _imported_names(name: str, path: Path) -> set:
    package = name if path.name == "__init__.py" else name.rsplit(".", 1)[0]
    names = set()
    for node in ast.walk(ast.parse(path.read_text(encoding="utf-8"))):
        if isinstance(node, ast.Import):
            names.update(alias.name for alias in node.names)
        elif isinstance(node, ast.ImportFrom):
            base = node.module or ""
            if node.level:  # relative import
                anchor = package.split(".")[:len(package.split(".")) - node.level + 1]
                base = ".".join(anchor + ([base] if base else []))
            names.update(f"{base}.{alias.name}" if f"{base}.{alias.name}" in MODULES else base
                         for alias in node.names)
    return names


def _resolve(name: str) -> str:
    """The defgg_ros module a dotted name lives in (a.b.c.func -> a.b.c), else the name itself."""
    while name not in MODULES and "." in name:
        name = name.rsplit(".", 1)[0]
    return name


IMPORTS = {name: {_resolve(n) for n in _imported_names(name, path)} - {name} for name, path in MODULES.items()}


def _package(module: str) -> str:
    """defgg_ros.model.inference -> model; a root module is a package of its own (constants, demo)."""
    parts = module.split(".")
    return parts[1] if len(parts) > 1 else "__init__"


def _cycles(graph: dict) -> list:
    """Strongly connected components with more than one member (Tarjan, iterative)."""
    index, low, on_stack, stack, found, counter = {}, {}, set(), [], [], [0]
    for start in graph:
        if start in index:
            continue
        work = [(start, iter(sorted(graph.get(start, ()))))]
        index[start] = low[start] = counter[0]
        counter[0] += 1
        stack.append(start)
        on_stack.add(start)
        while work:
            node, children = work[-1]
            child = next(children, None)
            if child is not None:
                if child not in index:
                    index[child] = low[child] = counter[0]
                    counter[0] += 1
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
                    found.append(frozenset(component))
    return found


def _package_graph() -> dict:
    graph = {}
    for module, imported in IMPORTS.items():
        for other in imported:
            if other in MODULES and _package(other) != _package(module):
                graph.setdefault(_package(module), set()).add(_package(other))
    return graph


def _internal_graph() -> dict:
    return {module: {m for m in imported if m in MODULES} for module, imported in IMPORTS.items()}


def test_the_walk_sees_the_package():
    assert len(MODULES) > 100 and "defgg_ros.model.inference" in MODULES
    assert "defgg_ros.grasping.geometry" in IMPORTS["defgg_ros.control.pick_place"]
    assert _cycles({"a": {"b"}, "b": {"a"}, "c": {"a"}}) == [frozenset({"a", "b"})]


def test_cores_import_neither_rclpy_nor_a_layer_above_them():
    bad = []
    for module, imported in sorted(IMPORTS.items()):
        if _package(module) not in CORES:
            continue
        for other in sorted(imported):
            if other.split(".")[0] in ROS_MODULES or (other in MODULES and _package(other) in ABOVE_CORES):
                bad.append(f"{module} imports {other}")
    assert not bad, "\n".join(bad)


def test_no_package_cycles():
    cycles = [sorted(c) for c in _cycles(_package_graph())]
    assert not cycles, f"import cycles between packages: {cycles}"


def test_no_module_cycles():
    cycles = [sorted(c) for c in _cycles(_internal_graph())]
    assert not cycles, f"import cycles between modules: {cycles}"
