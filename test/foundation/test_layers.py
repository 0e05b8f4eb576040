"""Layers point down, as the table below says: a walk of defgg_ros's import graph (every import statement, also
those inside functions) fails on an import between two packages that MAY_IMPORT does not list, on a package the
table does not place, on a cycle in the table itself, on an import cycle between packages or between modules,
and on a core package or a root module importing rclpy.

The layers, bottom up: the root modules (constants, errors, rotations, atomic, cli_help, provenance, stiffness,
grip_force, hertz, section_model, squeeze; every package may import them); the cores, no rclpy (grasping, control,
perception, model, sim, data, planning); offline above them (train, evaluation); the ROS side (ros: rclpy helpers
and names; nodes: thin adapters; bringup: the process launcher; sessions: record/replay; demo). A package added to
defgg_ros fails here until it has a row.
"""
import ast
from pathlib import Path

import pytest

pytestmark = pytest.mark.unit

PACKAGE_DIR = Path(__file__).resolve().parents[2] / "defgg_ros"
ROOT_MODULES = {"constants", "errors", "rotations", "atomic", "cli_help", "stiffness", "grip_force", "hertz",
                "section_model", "squeeze", "provenance"}
CORES = ("model", "grasping", "perception", "control", "sim", "data", "planning")
ROS_MODULES = ("rclpy", "rosidl_runtime_py", "rosbag2_py")
# Which package may import which (besides the root modules). Read a row as "<package> stands on these".
MAY_IMPORT = {
    # root modules among themselves
    "__init__": set(), "constants": set(), "errors": set(), "rotations": set(), "atomic": set(), "cli_help": set(),
    "provenance": set(),
    "stiffness": {"constants"}, "grip_force": {"constants"}, "hertz": set(), "section_model": {"constants", "hertz"},
    "squeeze": {"constants", "hertz", "section_model"},
    # cores
    "grasping": set(),
    "control": {"grasping"},
    "perception": {"control"},                       # the self filter needs the arm's kinematics
    "model": {"grasping", "perception"},              # inference ranks grasps, checks plausibility
    "sim": {"grasping"},
    "data": {"grasping", "model", "sim"},             # the generator runs trials; the dataset reads model inputs
    "planning": {"grasping", "control", "perception", "model"},
    # offline
    "train": {"grasping", "model", "data"},
    "evaluation": {"grasping", "model", "sim", "data", "ros", "bringup", "demo"},  # the cell experiment runs the cell
    # the ROS side
    "ros": {"perception"},                            # tf: the table pose and frame geometry
    "nodes": {"grasping", "control", "perception", "model", "sim", "planning", "ros"},
    "bringup": {"control", "perception", "sim", "ros"},     # starts the nodes as processes, imports none
    "sessions": {"perception", "model", "sim", "ros", "nodes", "bringup"},
    "demo": {"control", "perception", "model", "sim", "ros", "bringup"},
}

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


def forbidden_imports(imports: dict) -> list:
    """'a imports b' for every import between two packages that MAY_IMPORT does not allow."""
    bad = []
    for module, imported in sorted(imports.items()):
        package = _package(module)
        allowed = MAY_IMPORT.get(package, set()) | (ROOT_MODULES if package not in ROOT_MODULES else set())
        for other in sorted(imported):
            if other in MODULES and _package(other) != package and _package(other) not in allowed:
                bad.append(f"{module} ({package}) imports {other} ({_package(other)})")
    return bad


def test_every_package_has_a_row_and_every_row_a_package():
    packages = {_package(module) for module in MODULES}
    assert packages == set(MAY_IMPORT), (f"not in MAY_IMPORT: {sorted(packages - set(MAY_IMPORT))}; "
                                         f"no such package: {sorted(set(MAY_IMPORT) - packages)}")


def test_the_table_is_a_layering():
    table = {package: set(allowed) | (ROOT_MODULES if package not in ROOT_MODULES else set())
             for package, allowed in MAY_IMPORT.items()}
    assert not _cycles(table), f"MAY_IMPORT has a cycle: {[sorted(c) for c in _cycles(table)]}"


def test_every_import_between_packages_is_in_the_table():
    bad = forbidden_imports(IMPORTS)
    assert not bad, "imports MAY_IMPORT does not allow:\n" + "\n".join(bad)


def test_an_adapter_importing_a_sibling_adapter_is_caught():
    assert forbidden_imports({"defgg_ros.nodes.executor_node": {"defgg_ros.bringup.supervisor"}})
    assert forbidden_imports({"defgg_ros.grasping.geometry": {"defgg_ros.model.inference"}})
    assert not forbidden_imports({"defgg_ros.nodes.executor_node": {"defgg_ros.ros.topics", "defgg_ros.constants"}})


def test_cores_and_root_modules_do_not_import_rclpy():
    bad = [f"{module} imports {other}" for module, imported in sorted(IMPORTS.items())
           if _package(module) in CORES or _package(module) in ROOT_MODULES
           for other in sorted(imported) if other.split(".")[0] in ROS_MODULES]
    assert not bad, "\n".join(bad)


def test_no_package_cycles():
    cycles = [sorted(c) for c in _cycles(_package_graph())]
    assert not cycles, f"import cycles between packages: {cycles}"


def test_no_module_cycles():
    cycles = [sorted(c) for c in _cycles(_internal_graph())]
    assert not cycles, f"import cycles between modules: {cycles}"
