"""The simulated cell serves franka_ros2 3.x's contract as docs/franka_contract.md's table states it: every
topic of the table probed on a running fake driver (reliability and durability off the ROS graph, the history
depth on the driver's own publisher: the graph does not carry it), the names in each message, the rates in sim
time, the actions; and the MoveIt launch's merged joint states (fingers at 0.0, or absent)."""
import re
from pathlib import Path

import numpy as np
import pytest
from rclpy.parameter import Parameter
from rclpy.qos import DurabilityPolicy, ReliabilityPolicy

from defgg_ros.ros import topics

ROOT = Path(__file__).resolve().parents[2]
CONTRACT = ROOT / "docs" / "franka_contract.md"
SCENE = ROOT / "sim_bringup" / "scenes" / "rigid_box.yaml"
TIMEOUT_S = 30.0
CONTROL_PERIOD_S = 1e-3   # the driver's default robot_state_rate_hz: 1000


def contract_rows() -> list[dict]:
    """The 'Topics' table of docs/franka_contract.md: topic, type, reliability, depth (None: system default),
    durability, rate_hz."""
    text = CONTRACT.read_text(encoding="utf-8")
    table = text[text.index("| topic | type | franka_ros2 publisher | QoS | rate | read by |"):]
    rows = []
    for line in table.splitlines()[2:]:
        if not line.startswith("| `"):
            break
        cells = [c.strip() for c in line.strip("|").split("|")]
        qos_text = cells[3]
        depth = re.search(r"keep last (\d+)", qos_text)
        rows.append({"topic": cells[0].strip("`"), "type": cells[1].split(",")[0],
                     "reliability": ReliabilityPolicy.BEST_EFFORT if qos_text.startswith("best effort")
                     else ReliabilityPolicy.RELIABLE,
                     "depth": int(depth.group(1)) if depth else None,
                     "durability": DurabilityPolicy.TRANSIENT_LOCAL if "transient local" in qos_text
                     else DurabilityPolicy.VOLATILE,
                     "rate_hz": float(re.match(r"([\d.]+) Hz", cells[4]).group(1))})
    return rows


@pytest.mark.unit
def test_the_contract_table_lists_what_the_executor_reads():
    rows = {row["topic"]: row for row in contract_rows()}
    assert {topics.JOINT_STATES, topics.ARM_JOINT_STATES, topics.GRIPPER_JOINT_STATES,
            topics.EXTERNAL_WRENCH} <= set(rows)
    assert rows[topics.EXTERNAL_WRENCH]["reliability"] == ReliabilityPolicy.BEST_EFFORT
    assert rows[topics.EXTERNAL_WRENCH]["depth"] == 1 and rows[topics.GRIPPER_JOINT_STATES]["depth"] == 1


def _driver(executor, **parameters):
    from defgg_ros.nodes.fake_panda_driver_node import FakePandaDriver

    node = FakePandaDriver(context=executor.context, parameter_overrides=[
        Parameter("scene_file", value=str(SCENE)), Parameter("depth_rate_hz", value=0.01),
        *[Parameter(name, value=value) for name, value in parameters.items()]])
    executor.add_node(node)
    return node


def _publisher_of(driver, topic):
    resolved = driver.resolve_topic_name(topic)
    return next(p for p in driver.publishers if p.topic_name == resolved)


def _record(executor, client, rows):
    from geometry_msgs.msg import PoseStamped, WrenchStamped
    from sensor_msgs.msg import JointState

    from defgg_ros.ros import qos

    types = {"sensor_msgs/JointState": JointState, "geometry_msgs/WrenchStamped": WrenchStamped,
             "geometry_msgs/PoseStamped": PoseStamped}
    seen = {row["topic"]: [] for row in rows}
    for row in rows:
        client.create_subscription(types[row["type"]], row["topic"], seen[row["topic"]].append, qos.ROBOT_STATE_READ)
    return seen


@pytest.mark.parametrize("robot_type", ["fer", "fr3"])
def test_every_franka_topic_has_the_contracts_qos_names_and_rate(executor, spin, robot_type):
    from rclpy.action import get_action_server_names_and_types_by_node
    from rclpy.node import Node

    names = topics.robot_names(robot_type)
    driver = _driver(executor, robot_type=robot_type, max_real_time_factor=0.0)
    client = Node("contract_probe", context=executor.context)
    executor.add_node(client)
    rows = contract_rows()
    seen = _record(executor, client, rows)
    try:
        spin(executor, lambda: all(len(seen[r["topic"]]) >= 20 for r in rows), TIMEOUT_S, "20 messages on each topic")
        for row in rows:
            topic = row["topic"]
            offered = client.get_publishers_info_by_topic("/" + topic)
            assert [i.node_name for i in offered] == ["fake_panda_driver"], topic
            assert offered[0].qos_profile.reliability == row["reliability"], topic
            assert offered[0].qos_profile.durability == row["durability"], topic
            if row["depth"] is not None:
                assert _publisher_of(driver, topic).qos_profile.depth == row["depth"], topic
            # The rate in sim time: every stamp a whole number of the topic's periods (a reader drops most of
            # the 1 kHz ones, so gaps are multiples, not the period), and the periods not all of a slower rate.
            stamps_s = np.array([m.header.stamp.sec + m.header.stamp.nanosec * 1e-9 for m in seen[topic]])
            periods = stamps_s * row["rate_hz"]
            # slower rates land on the 1 ms control period's grid: up to one control period off their slot
            periods_per_slot = row["rate_hz"] * CONTROL_PERIOD_S
            slot_jitter = max(1e-3, periods_per_slot) if periods_per_slot < 1 else 1e-3
            assert np.allclose(periods, np.round(periods), atol=slot_jitter), (topic, stamps_s[:5])
            assert len(set(np.round(periods).astype(int) % 10)) > 1, (topic, "stamps all on a 10x slower grid")
        arm = seen[topics.ARM_JOINT_STATES][-1]
        assert tuple(arm.name) == names["joints"]
        assert tuple(seen[topics.MEASURED_JOINT_STATES][-1].name) == names["joints"]
        fingers = seen[topics.GRIPPER_JOINT_STATES][-1]
        assert tuple(fingers.name) == names["fingers"] and fingers.position[0] == fingers.position[1] > 0.03
        merged = seen[topics.JOINT_STATES][-1]
        assert tuple(merged.name) == names["joints"] + names["fingers"]
        # franka_robot_state_broadcaster stamps the URDF's root link, `base` (= base_frame): docs' "Frames"
        assert seen[topics.EXTERNAL_WRENCH][-1].header.frame_id == topics.FRANKA_STATE_FRAME
        assert seen[topics.CURRENT_POSE][-1].header.frame_id == topics.FRANKA_STATE_FRAME
        assert arm.header.frame_id == topics.JOINT_STATE_BROADCASTER_FRAME and merged.header.frame_id == ""
        actions = {name for name, _ in get_action_server_names_and_types_by_node(client, "fake_panda_driver", "/")}
        assert {"/" + names["trajectory_action"], "/franka_gripper/move", "/franka_gripper/grasp",
                "/franka_gripper/homing"} <= actions
    finally:
        driver.shutdown()


@pytest.mark.parametrize("mode", ["urdf_default", "none"])
def test_the_moveit_launchs_merged_joint_states(executor, spin, mode):
    """moveit.launch.py merges fr3_gripper/joint_states, which nobody publishes: the fingers stay at the URDF
    default 0.0 m (urdf_default), or a merger without the hand has none; the gripper's own topic still has them."""
    from rclpy.node import Node

    from defgg_ros.ros import qos

    names = topics.robot_names("fr3")
    driver = _driver(executor, robot_type="fr3", joint_state_fingers=mode)
    client = Node("moveit_probe", context=executor.context)
    executor.add_node(client)
    from sensor_msgs.msg import JointState

    merged, gripper = [], []
    client.create_subscription(JointState, topics.JOINT_STATES, merged.append, qos.ROBOT_STATE_READ)
    client.create_subscription(JointState, topics.GRIPPER_JOINT_STATES, gripper.append, qos.ROBOT_STATE_READ)
    try:
        spin(executor, lambda: len(merged) >= 3 and gripper, TIMEOUT_S, "merged and gripper joint states")
        if mode == "none":
            assert tuple(merged[-1].name) == names["joints"]
        else:
            assert tuple(merged[-1].name) == names["joints"] + names["fingers"]
            assert list(merged[-1].position[7:]) == [0.0, 0.0]
        assert sum(gripper[-1].position) > 0.07   # the fingers are open: the gripper's own topic says so
    finally:
        driver.shutdown()
