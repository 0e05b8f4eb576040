"""sim_bringup/launch/{real_cell,sim_cell}.launch.py start what `defgg-bringup` starts.

ROS 2's `launch` and `launch_ros` are not on PyPI, so the files are loaded against a stand-in of the few
classes they use (test/support/launch_recorder/) and evaluated as `ros2 launch` would before starting
anything. Checked: each node runs one of this package's console scripts (setup.py) whose module is the node
set's; its parameter files exist and are installed; every parameter it is given is in the node's schema; and the
nodes, their files and their effective parameters equal the bringup's node set (real_cell for robot_type fr3,
real_cell_fer for fer, sim_cell). The launch files are installed once, to share/defgg_ros/launch.
"""
import sys
import types
from pathlib import Path

import pytest
import yaml
from support.setup_capture import console_scripts, installed_files

from defgg_ros.bringup.node_set import NodeEntry, ReadyCheck, load_node_set
from defgg_ros.bringup.shared_parameters import disagreements, effective_parameters
from defgg_ros.ros.parameters import load_schema

pytestmark = pytest.mark.unit

REPO = Path(__file__).resolve().parents[2]
LAUNCH_DIR = REPO / "sim_bringup" / "launch"
RECORDER_DIR = REPO / "test" / "support" / "launch_recorder"
ROS_BUILTIN_PARAMETERS = {"use_sim_time"}
# the launch arguments -> the bringup's node set they reproduce
CASES = {
    "real_cell-fr3": ("real_cell.launch.py", {"robot_type": "fr3"}, "real_cell"),
    "real_cell-default": ("real_cell.launch.py", {}, "real_cell"),
    "real_cell-fer": ("real_cell.launch.py", {"robot_type": "fer"}, "real_cell_fer"),
    "sim_cell": ("sim_cell.launch.py", {}, "sim_cell"),
}


@pytest.fixture(scope="module")
def recorder():
    """The stand-in `launch`/`launch_ros` on sys.path for this module only (nothing else may import them)."""
    saved_path, saved_modules = list(sys.path), set(sys.modules)
    sys.path.insert(0, str(RECORDER_DIR))
    try:
        import recorder as module
        yield module
    finally:
        sys.path[:] = saved_path
        for name in set(sys.modules) - saved_modules:
            if name.split(".")[0] in ("launch", "launch_ros", "recorder"):
                del sys.modules[name]


def load_launch_file(path: Path):
    """Executed from source (no __pycache__ left in sim_bringup/launch, which would be installed)."""
    module = types.ModuleType(path.stem.replace(".", "_"))
    module.__file__ = str(path)
    exec(compile(path.read_text(encoding="utf-8"), str(path), "exec"), module.__dict__)  # noqa: S102
    return module.generate_launch_description()


def evaluate(recorder, file_name: str, arguments: dict):
    return recorder.evaluate(load_launch_file(LAUNCH_DIR / file_name), arguments, {"defgg_ros": REPO})


def file_parameters(path: str, node: str) -> dict:
    raw = yaml.safe_load(Path(path).read_text(encoding="utf-8")) or {}
    params = {}
    for key in ("/**", node, f"/{node}", f"/**/{node}"):
        params.update((raw.get(key) or {}).get("ros__parameters") or {})
    return params


def launch_effective(started) -> dict:
    """What the node starts with, resolved as the bringup resolves a node set's entry (schema defaults, the files
    in order, then the dicts; names left empty follow robot_type), plus use_sim_time when given."""
    kinds = [kind for kind, _ in started.parameter_order]
    assert kinds == sorted(kinds, key=["file", "dict"].index), f"{started.name}: a file after a dict: {kinds}"
    entry = NodeEntry(started.name, "", tuple(started.parameter_files), ReadyCheck("service", "/unused"),
                      dict(started.parameter_values))
    values = effective_parameters(entry)
    if "use_sim_time" in started.parameter_values:
        values["use_sim_time"] = started.parameter_values["use_sim_time"]
    return values


@pytest.mark.parametrize("case", sorted(CASES))
def test_the_launch_file_starts_the_bringups_node_set(recorder, case):
    file_name, arguments, set_name = CASES[case]
    started = {node.name: node for node in evaluate(recorder, file_name, arguments).nodes}
    node_set = load_node_set(set_name)
    entries = {entry.name: entry for entry in node_set.nodes}
    assert sorted(started) == sorted(entries)
    scripts = console_scripts()
    for name, node in started.items():
        entry = entries[name]
        assert node.package == "defgg_ros" and node.namespace == ""
        assert scripts.get(node.executable) == entry.module, f"{name}: {node.executable} is not {entry.module}"
        assert [str(Path(p).resolve()) for p in node.parameter_files] == list(entry.params_files), name
        expected = effective_parameters(entry)
        if node_set.use_sim_time:
            expected["use_sim_time"] = True
        got = launch_effective(node)
        assert {k: got[k] for k in expected} == expected, name
        assert got.get("use_sim_time", False) == node_set.use_sim_time, name
    assert not disagreements(node_set)


@pytest.mark.parametrize("case", sorted(CASES))
def test_every_file_exists_is_installed_and_sets_only_schema_parameters(recorder, case):
    file_name, arguments, _ = CASES[case]
    installed = installed_files()
    for node in evaluate(recorder, file_name, arguments).nodes:
        schema = load_schema(node.name)
        for path in node.parameter_files:
            assert Path(path).is_file(), path
            destination = str(Path("share/defgg_ros") / Path(path).relative_to(REPO))
            assert installed.get(destination) == str(Path(path).relative_to(REPO)), f"{destination} not installed"
            unknown = set(file_parameters(path, node.name)) - set(schema)
            assert not unknown, f"{path}: {node.name} has no parameter {sorted(unknown)}"
        unknown = set(node.parameter_values) - set(schema) - ROS_BUILTIN_PARAMETERS
        assert not unknown, f"{file_name}: {node.name} has no parameter {sorted(unknown)}"


def test_launch_files_are_installed_once_to_share_launch():
    installed = installed_files()
    for path in sorted(LAUNCH_DIR.glob("*.launch.py")):
        found = [dest for dest in installed if Path(dest).name == path.name]
        assert found == [f"share/defgg_ros/launch/{path.name}"], found   # ros2 launch refuses a name found twice
    assert {Path(p).name for p in LAUNCH_DIR.glob("*.launch.py")} == {"real_cell.launch.py", "sim_cell.launch.py"}


def test_real_cell_arguments_move_the_nodes_and_the_camera_topics(recorder):
    result = evaluate(recorder, "real_cell.launch.py", {"namespace": "left", "camera_namespace": "/wrist/d405",
                                                        "robot_type": "fer"})
    assert {node.namespace for node in result.nodes} == {"left"}
    readers = {node.name: node for node in result.nodes if "depth_topic" in node.parameter_values}
    assert sorted(readers) == ["grasp_inference_node", "segmentation_node"]
    for node in readers.values():
        assert node.parameter_values["depth_topic"] == "/wrist/d405/depth/image_rect_raw"
        assert node.parameter_values["camera_info_topic"] == "/wrist/d405/depth/camera_info"
    assert result.arguments["config_file"] == str(REPO / "sim_bringup" / "config" / "real_cell" / "fer.yaml")


def test_real_cell_takes_a_config_file_and_refuses_an_unknown_robot_type(recorder, tmp_path):
    own = tmp_path / "my_cell.yaml"
    own.write_text("executor_node:\n  ros__parameters: {limits_scale: 0.5}\n")
    result = evaluate(recorder, "real_cell.launch.py", {"config_file": str(own)})
    executor = next(node for node in result.nodes if node.name == "executor_node")
    assert executor.parameter_files[-1] == str(own) and launch_effective(executor)["limits_scale"] == 0.5
    with pytest.raises(ValueError, match="panda"):
        evaluate(recorder, "real_cell.launch.py", {"robot_type": "panda"})


def test_the_simulated_cell_keeps_discovery_on_this_host(recorder):
    assert evaluate(recorder, "sim_cell.launch.py", {}).environment == {"ROS_AUTOMATIC_DISCOVERY_RANGE": "LOCALHOST"}
