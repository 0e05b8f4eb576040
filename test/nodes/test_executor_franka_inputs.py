"""The executor reads franka_ros2 3.x's topics whatever QoS they are offered with (issue 46): a best-effort
wrench as franka_robot_state_broadcaster >= 3.3.0 publishes it; the finger width from franka_gripper's own
joint states when the merged ones lack the fingers or hold the MoveIt launch's constant 0.0; the arm from
franka/joint_states when joint_states has no publisher; and a silent input named with what the graph shows.
Real rclpy nodes over DDS; the publishers use the QoS franka_ros2 offers (docs/franka_contract.md)."""
import pytest
from builtin_interfaces.msg import Time
from geometry_msgs.msg import WrenchStamped
from rclpy.node import Node
from rclpy.parameter import Parameter
from sensor_msgs.msg import JointState

from defgg_ros.constants import PANDA_READY_Q_RAD
from defgg_ros.nodes.executor_node import ExecutorNode, GoalError
from defgg_ros.nodes.topic_watch import TopicWatch
from defgg_ros.ros import qos, topics

NAMES = topics.robot_names()   # fer
TIMEOUT_S = 10.0
PUBLISH_PERIOD_S = 0.02


def _start(executor, **parameters):
    node = ExecutorNode(context=executor.context,
                        parameter_overrides=[Parameter(k, value=v) for k, v in parameters.items()])
    franka = Node("franka_stand_in", context=executor.context)
    executor.add_node(node)
    executor.add_node(franka)
    return node, franka


def _publish_periodically(node, msg_type, topic, profile, make):
    publisher = node.create_publisher(msg_type, topic, profile)
    node.create_timer(PUBLISH_PERIOD_S, lambda: publisher.publish(make()))
    return publisher


def _arm_state(with_fingers_m=None) -> JointState:
    names, position = list(NAMES["joints"]), list(PANDA_READY_Q_RAD)
    if with_fingers_m is not None:
        names += list(NAMES["fingers"])
        position += [with_fingers_m, with_fingers_m]
    return JointState(name=names, position=position, velocity=[0.0] * len(names))


def _gripper_state(each_finger_m) -> JointState:
    return JointState(name=list(NAMES["fingers"]), position=[each_finger_m] * 2, velocity=[0.0] * 2)


def test_a_best_effort_wrench_as_franka_publishes_it_reaches_the_executor(executor, spin):
    """Before issue 46 the executor read the wrench reliable: nothing arrived and every goal aborted in the
    contact guard ("no external wrench")."""
    node, franka = _start(executor)

    def wrench():
        msg = WrenchStamped()
        msg.header.frame_id, msg.wrench.force.z = topics.FRANKA_STATE_FRAME, 3.5   # the URDF root, as franka's
        return msg

    _publish_periodically(franka, WrenchStamped, topics.EXTERNAL_WRENCH, qos.FRANKA_CONVENIENCE, wrench)
    spin(executor, lambda: node._last_force_wall_s is not None, TIMEOUT_S, "a best-effort wrench at the executor")
    assert node._last_force[2] == pytest.approx(3.5)


@pytest.mark.parametrize("merged_fingers_m", [None, 0.0], ids=["no_fingers", "moveit_default_zero"])
def test_the_finger_width_comes_from_franka_gripper_when_joint_states_lack_it(executor, spin, merged_fingers_m):
    """franka.launch.py merges the fingers into joint_states; moveit.launch.py leaves them at the URDF's 0.0 (or
    a merger without the hand has none): franka_gripper/joint_states (depth 1, reliable) is read first."""
    node, franka = _start(executor)
    _publish_periodically(franka, JointState, topics.JOINT_STATES, qos.JOINT_STATE_PUBLISHER,
                          lambda: _arm_state(merged_fingers_m))
    _publish_periodically(franka, JointState, topics.GRIPPER_JOINT_STATES, qos.GRIPPER_STATE,
                          lambda: _gripper_state(0.03))

    def width_m():
        return node._last_state[0].gripper_width_m if node._last_state is not None else None

    spin(executor, lambda: width_m() == pytest.approx(0.06), TIMEOUT_S, "the gripper's width in the arm state")
    with node._lock:
        assert node._gripper_width_m() == pytest.approx(0.06)


def test_the_arm_is_read_from_franka_joint_states_when_joint_states_has_no_publisher(executor, spin):
    node, franka = _start(executor, silent_topic_s=0.5)
    _publish_periodically(franka, JointState, topics.ARM_JOINT_STATES, qos.FRANKA_SYSTEM_DEFAULT, _arm_state)
    spin(executor, lambda: node._last_state is not None, TIMEOUT_S, "the arm from franka/joint_states")
    assert node._arm_topic_watch.resolved == "/franka/joint_states"


def test_a_silent_input_is_named_with_its_publishers_and_their_qos(executor, spin):
    """The goal's failure reason says which topic is silent, who publishes it with which QoS, and this reader's."""
    node, franka = _start(executor, external_wrench_topic="silent/wrench")
    _publish_periodically(franka, JointState, topics.JOINT_STATES, qos.JOINT_STATE_PUBLISHER,
                          lambda: _arm_state(0.04))
    franka.create_publisher(WrenchStamped, "silent/wrench", qos.FRANKA_CONVENIENCE)   # never publishes
    spin(executor, lambda: node._last_state is not None and node._wrench_watch.publishers()
         and node._wrench_watch.silent_s() > 1.0, TIMEOUT_S, "joint states, the silent publisher on the graph")
    with pytest.raises(GoalError) as error:
        node._check_inputs({**node._params(), "watchdog_timeout_s": 1.0})
    text = str(error.value)
    assert "no message on /silent/wrench" in text and "(none since start)" in text
    assert "1 publisher(s) (/franka_stand_in: best effort, volatile)" in text
    assert "this reader: best effort, keep last 1, volatile" in text
    assert "the publishers send nothing" in text and "franka_robot_state_broadcaster" in text


def test_the_diagnosis_tells_a_qos_mismatch_from_no_publisher(executor, spin):
    prober = Node("qos_prober", context=executor.context)
    executor.add_node(prober)
    reliable_reader = TopicWatch(prober, topics.EXTERNAL_WRENCH, qos.STATE)
    assert "no publisher on the graph" in reliable_reader.diagnosis()
    prober.create_publisher(WrenchStamped, topics.EXTERNAL_WRENCH, qos.FRANKA_CONVENIENCE)
    spin(executor, reliable_reader.publishers, TIMEOUT_S, "the publisher on the graph")
    text = reliable_reader.diagnosis()
    assert "best effort" in text and "this reader: reliable, keep last 10" in text
    assert text.endswith("a reliable reader gets nothing from a best-effort publisher")


def test_a_silent_input_is_reported_in_the_log(executor, spin):
    """Without a goal to fail, the operator learns it from the executor's log (after silent_topic_s)."""
    from rcl_interfaces.msg import Log
    from rclpy.qos import DurabilityPolicy, QoSProfile, ReliabilityPolicy

    node, franka = _start(executor, silent_topic_s=0.5)
    lines = []
    franka.create_subscription(Log, "/rosout", lambda m: lines.append(m.msg) if m.name == "executor_node" else None,
                               QoSProfile(depth=100, reliability=ReliabilityPolicy.RELIABLE,
                                          durability=DurabilityPolicy.TRANSIENT_LOCAL))
    franka.create_publisher(WrenchStamped, topics.EXTERNAL_WRENCH, qos.FRANKA_CONVENIENCE)   # never publishes

    def reported():
        return any(f"no message on /{topics.EXTERNAL_WRENCH}" in line and "1 publisher(s)" in line for line in lines)

    spin(executor, reported, TIMEOUT_S, "the silent wrench in the executor's log")


def test_with_use_sim_time_a_goal_waits_for_the_clock_and_is_refused_without_it(executor, spin):
    """Joint states and the wrench arrive but no /clock yet: a sequence started at robot time 0 would see its
    first tick jump to the simulator's time; the goal waits for the clock, then is refused naming it."""
    from rosgraph_msgs.msg import Clock

    node, franka = _start(executor, use_sim_time=True)
    _publish_periodically(franka, JointState, topics.JOINT_STATES, qos.JOINT_STATE_PUBLISHER,
                          lambda: _arm_state(0.04))
    _publish_periodically(franka, WrenchStamped, topics.EXTERNAL_WRENCH, qos.FRANKA_CONVENIENCE, WrenchStamped)
    spin(executor, lambda: node._last_state is not None and node._last_force_wall_s is not None, TIMEOUT_S,
         "joint states and the wrench at the executor")
    node._wait_for_first_inputs(0.3)   # no clock: it waits its time out, then the check names the clock
    with pytest.raises(GoalError, match="no clock: use_sim_time is true"):
        node._check_inputs({**node._params(), "watchdog_timeout_s": 5.0})
    clock = franka.create_publisher(Clock, topics.CLOCK, qos.STATE)
    spin(executor, lambda: clock.publish(Clock(clock=Time(sec=12))) or node.get_clock().now().nanoseconds > 0,
         TIMEOUT_S, "the sim clock at the executor")
    node._check_inputs({**node._params(), "watchdog_timeout_s": 5.0})
