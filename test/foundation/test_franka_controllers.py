"""sim_bringup/config/franka/controllers.yaml: the ros2_control file a real cell passes to franka_ros2's
`franka.launch.py controllers_yaml:=...` so that an arm controller serves FollowJointTrajectory without MoveIt.

Checked against franka_ros2 v3.4.0's conventions (docs/real_cell.md, "Facts this page relies on"): a
namespace-agnostic file (`/**:` -> controller_manager -> ros__parameters, then one `/**:` section per
controller), the two broadcasters franka.launch.py spawns by name, and per robot type a
JointTrajectoryController with franka_fr3_moveit_config's effort interface, states and gains. The real-cell
parameter files must send the executor's trajectories to exactly those controllers.
"""
from pathlib import Path

import pytest
import yaml

from defgg_ros.bringup.node_set import load_node_set
from defgg_ros.bringup.shared_parameters import effective_parameters
from defgg_ros.constants import FRANKA_JTC_GAINS_PD
from defgg_ros.ros import topics

pytestmark = pytest.mark.unit

REPO = Path(__file__).resolve().parents[2]
CONTROLLERS = REPO / "sim_bringup" / "config" / "franka" / "controllers.yaml"
# The real-cell node set of each robot type (sim_bringup/config/<set>.yaml)
REAL_CELL_SETS = {"fr3": "real_cell", "fer": "real_cell_fer"}
JTC = "joint_trajectory_controller/JointTrajectoryController"
# franka.launch.py (v3.4.0) spawns these two by name; their types as in franka_bringup/config/controllers.yaml
BROADCASTERS = {"joint_state_broadcaster": "joint_state_broadcaster/JointStateBroadcaster",
                "franka_robot_state_broadcaster": "franka_robot_state_broadcaster/FrankaRobotStateBroadcaster"}


class _MergingLoader(yaml.SafeLoader):
    """ROS 2 parameter files may repeat a key (franka's repeat `/**:` once per section): rcl merges the
    repeats, PyYAML would keep only the last. This loader merges them, as rcl does."""


def _merge(into: dict, new: dict) -> dict:
    for key, value in new.items():
        if isinstance(value, dict) and isinstance(into.get(key), dict):
            _merge(into[key], value)
        else:
            into[key] = value
    return into


def _construct_merged_mapping(loader, node):
    loader.flatten_mapping(node)
    merged = {}
    for key_node, value_node in node.value:
        key = loader.construct_object(key_node, deep=True)
        value = loader.construct_object(value_node, deep=True)
        if isinstance(value, dict) and isinstance(merged.get(key), dict):
            _merge(merged[key], value)
        else:
            merged[key] = value
    return merged


_MergingLoader.add_constructor(yaml.resolver.BaseResolver.DEFAULT_MAPPING_TAG, _construct_merged_mapping)


def load_ros_parameter_file(path: Path) -> dict:
    return yaml.load(path.read_text(encoding="utf-8"), Loader=_MergingLoader)  # noqa: S506 (a SafeLoader)


def controller_manager_entries(raw: dict) -> dict:
    return raw["/**"]["controller_manager"]["ros__parameters"]


def test_the_file_is_namespace_agnostic_like_franka_bringups():
    raw = load_ros_parameter_file(CONTROLLERS)
    assert list(raw) == ["/**"], "franka.launch.py's namespace:= only applies to a `/**:` file"
    # one `/**:` root: any YAML reader sees every section (franka's repeated `/**:` needs rcl's merging)
    assert yaml.safe_load(CONTROLLERS.read_text(encoding="utf-8")) == raw
    for node, section in raw["/**"].items():
        assert list(section) == ["ros__parameters"], f"{node}: a node section holds only ros__parameters"
    manager = controller_manager_entries(raw)
    assert manager["update_rate"] == 1000   # franka_bringup's controller manager runs at 1 kHz


def test_the_broadcasters_franka_launch_spawns_are_declared_with_their_types():
    manager = controller_manager_entries(load_ros_parameter_file(CONTROLLERS))
    for name, plugin in BROADCASTERS.items():
        assert manager.get(name, {}).get("type") == plugin, name
    assert manager["franka_robot_state_broadcaster"]["state_interfaces"] == "robot_state"


@pytest.mark.parametrize("robot_type", sorted(REAL_CELL_SETS))
def test_one_effort_trajectory_controller_per_robot_type_with_frankas_gains(robot_type):
    raw = load_ros_parameter_file(CONTROLLERS)
    name = topics.robot_names(robot_type)["arm_controller"]
    assert controller_manager_entries(raw)[name]["type"] == JTC
    params = raw["/**"][name]["ros__parameters"]
    joints = [f"{robot_type}_joint{i}" for i in range(1, 8)]
    assert params["joints"] == joints
    assert params["command_interfaces"] == ["effort"]
    assert params["state_interfaces"] == ["position", "velocity"]
    assert list(params["gains"]) == joints
    for joint, (p, d) in zip(joints, FRANKA_JTC_GAINS_PD):
        gains = params["gains"][joint]
        assert (gains["p"], gains["d"], gains["i"]) == (p, d, 0.0), joint


def test_every_controller_with_parameters_has_a_type():
    raw = load_ros_parameter_file(CONTROLLERS)
    manager = controller_manager_entries(raw)
    for node in raw["/**"]:
        if node != "controller_manager":
            assert "type" in manager.get(node, {}), f"{node} has parameters but no type in controller_manager"


def _executor_trajectory_action(effective: dict) -> str:
    # an empty name parameter means "the robot type's name" (defgg_ros/ros/topics.py, robot_names)
    return effective["arm_trajectory_action"] or topics.robot_names(effective["robot_type"])["trajectory_action"]


@pytest.mark.parametrize("robot_type", sorted(REAL_CELL_SETS))
def test_the_real_cell_parameter_files_point_the_executor_at_the_controller(robot_type):
    node_set = load_node_set(REAL_CELL_SETS[robot_type])
    executor = next(entry for entry in node_set.nodes if entry.name == "executor_node")
    effective = effective_parameters(executor)
    assert effective["robot_type"] == robot_type
    controller, _, action = _executor_trajectory_action(effective).rpartition("/")
    assert action == "follow_joint_trajectory"
    raw = load_ros_parameter_file(CONTROLLERS)
    assert controller_manager_entries(raw).get(controller, {}).get("type") == JTC, \
        f"the executor sends to {controller}, which {CONTROLLERS.name} does not define"
    assert tuple(raw["/**"][controller]["ros__parameters"]["joints"]) == topics.robot_names(robot_type)["joints"]


def test_the_merging_loader_keeps_every_repeated_section(tmp_path):
    path = tmp_path / "two.yaml"
    path.write_text("/**:\n  a:\n    ros__parameters: {x: 1}\n/**:\n  b:\n    ros__parameters: {y: 2}\n")
    assert load_ros_parameter_file(path) == {"/**": {"a": {"ros__parameters": {"x": 1}},
                                                     "b": {"ros__parameters": {"y": 2}}}}
