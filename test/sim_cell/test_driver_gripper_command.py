"""franka_gripper's `gripper_action` (control_msgs/GripperCommand) and `stop` (std_srvs/Trigger) on the simulated
driver, over real DDS, as franka_ros2 3.4.0's gripper_action_server.cpp serves them (docs/franka_contract.md, "The
gripper's GripperCommand and stop"): the width is twice command.position; opening moves, closing grasps with
max_effort as the force and the default epsilons (5 mm); the result's position is the width, effort 0 and stalled
false whatever happened; `stop` ends the running command, whose goal (Move, Grasp or GripperCommand) is aborted."""
from pathlib import Path

import numpy as np
import pybullet as p
import pytest
from rclpy.parameter import Parameter

from defgg_ros.ros import topics

pytestmark = pytest.mark.ros

SCENES = Path(__file__).resolve().parents[2] / "sim_bringup" / "scenes"
TIMEOUT_S = 30.0
SUCCEEDED, CANCELED, ABORTED = 4, 5, 6   # action_msgs/GoalStatus


def _driver(executor, namespace="", real_time=False):
    from defgg_ros.nodes.fake_panda_driver_node import FakePandaDriver

    node = FakePandaDriver(context=executor.context, namespace=namespace, parameter_overrides=[
        Parameter("scene_file", value=str(SCENES / "rigid_box.yaml")),
        # 1: a gripper command takes its sim time in wall time, so a stop reaches it while it runs
        Parameter("max_real_time_factor", value=1.0 if real_time else 0.0)])
    executor.add_node(node)
    return node


@pytest.fixture
def client(executor):
    from rclpy.node import Node

    node = Node("gripper_command_test_client", context=executor.context)
    executor.add_node(node)
    return node


class Gripper:
    """Clients of the driver's gripper interfaces, and the finger width from franka_gripper/joint_states."""

    def __init__(self, executor, client, spin, prefix=""):
        from control_msgs.action import GripperCommand
        from franka_msgs.action import Grasp, Move
        from sensor_msgs.msg import JointState
        from std_srvs.srv import Trigger

        from defgg_ros.ros import qos
        from defgg_ros.ros.action import ActionClient

        self.executor, self.spin = executor, spin
        self.command = ActionClient(client, GripperCommand, prefix + topics.GRIPPER_COMMAND_ACTION)
        self.move = ActionClient(client, Move, prefix + topics.GRIPPER_MOVE_ACTION)
        self.grasp = ActionClient(client, Grasp, prefix + topics.GRIPPER_GRASP_ACTION)
        self.stop = client.create_client(Trigger, prefix + topics.GRIPPER_STOP_SERVICE)
        self.fingers = []
        client.create_subscription(JointState, prefix + topics.GRIPPER_JOINT_STATES, self.fingers.append,
                                   qos.ROBOT_STATE_READ)
        spin(executor, lambda: self.fingers and self.command.server_is_ready() and self.move.server_is_ready()
             and self.grasp.server_is_ready() and self.stop.service_is_ready(), TIMEOUT_S,
             "the gripper's gripper_action, move, grasp and stop")

    def width_m(self) -> float:
        return float(sum(self.fingers[-1].position))

    def steady_width_m(self):
        """The width when the last three finger states agree within 10 um, else None."""
        widths = [sum(m.position) for m in self.fingers[-3:]]
        return float(widths[-1]) if len(widths) == 3 and max(widths) - min(widths) < 1e-5 else None

    def send(self, action, goal, feedback=None):
        handle = self.spin(self.executor, action.send_goal_async(goal, feedback_callback=feedback), TIMEOUT_S,
                           "goal accepted")
        assert handle.accepted
        return handle

    def result(self, handle):
        return self.spin(self.executor, handle.get_result_async(), TIMEOUT_S, "the gripper goal's result")

    def gripper_command(self, position, max_effort, feedback=None):
        from control_msgs.action import GripperCommand
        from control_msgs.msg import GripperCommand as Command

        goal = GripperCommand.Goal(command=Command(position=position, max_effort=max_effort))
        return self.result(self.send(self.command, goal, feedback))

    def call_stop(self, call):
        from std_srvs.srv import Trigger

        return call(self.executor, self.stop, Trigger.Request(), TIMEOUT_S, "the stop service")


def _over_the_box(driver, executor, spin):
    """The hand down around the scene's box (a trajectory on the driver's own cell), the fingers open."""
    cell = driver.cell
    with driver._lock:
        box_xyz, _ = cell.object_poses()[0]
        yaw = cell.scene.objects[0].yaw_rad
        quat = p.getQuaternionFromEuler([np.pi, 0.0, yaw])

        def ik(xyz):
            q = p.calculateInverseKinematics(cell.robot, cell.tcp_link, list(xyz), quat, maxNumIterations=200,
                                             residualThreshold=1e-5, physicsClientId=cell.client)
            return np.array(q[:7])

        above, at = ik(box_xyz + [0, 0, 0.15]), ik(box_xyz)
        cell.command_trajectory([(1.5, above, None, None), (2.5, at, None, None)])
        done_s = cell.time_s + 2.8
    spin(executor, lambda: driver.cell.time_s >= done_s, TIMEOUT_S, "the hand around the box")
    return cell.scene.objects[0].size_m[0]


def _pad_forces_n(driver):
    """Each finger's contact normal force on the box."""
    cell = driver.cell
    with driver._lock:
        box = cell.object_ids[0]
        return [sum(c[9] for c in p.getContactPoints(cell.robot, box, joint, -1, physicsClientId=cell.client))
                for joint in cell.finger_joints]


def test_gripper_action_takes_position_per_finger_and_reports_the_width(executor, client, spin):
    """Opening is a move to 2 x position (reached_goal, the width in `position`, feedback of the width); closing on
    nothing is a grasp that closes fully and ends outside its 5 mm band (aborted); the same position succeeds at
    once; a width outside [0, max_width] is aborted with an empty result."""
    _driver(executor)
    gripper = Gripper(executor, client, spin)
    assert gripper.width_m() == pytest.approx(0.08, abs=0.002)   # the simulated hand starts open

    # Closing from 80 to 30 mm with nothing between the fingers: franka_gripper grasps (closing), the fingers close
    # fully and stop outside [25, 35] mm: grasp() returned false.
    answer = gripper.gripper_command(0.015, 20.0)
    assert answer.status == ABORTED
    r = answer.result
    assert (r.reached_goal, r.stalled, r.effort) == (False, False, 0.0) and r.position < 0.01, r

    feedback = []
    answer = gripper.gripper_command(0.03, 20.0, feedback.append)   # opening to 60 mm: a move
    assert answer.status == SUCCEEDED
    r = answer.result
    assert r.reached_goal and not r.stalled and r.effort == 0.0, r
    assert r.position == pytest.approx(0.06, abs=0.002)             # the width, not a finger's 0.03
    assert feedback and all(f.feedback.effort == 0.0 and not f.feedback.stalled for f in feedback)
    assert 0.0 <= feedback[-1].feedback.position <= 0.062
    spin(executor, lambda: gripper.steady_width_m() is not None and abs(gripper.width_m() - 0.06) < 0.002,
         TIMEOUT_S, "franka_gripper/joint_states steady at 60 mm")

    width_m = gripper.steady_width_m()
    answer = gripper.gripper_command(width_m / 2, 20.0)   # already there (within 0.1 mm): success without a command
    assert answer.status == SUCCEEDED and answer.result.reached_goal
    assert answer.result.position == pytest.approx(width_m, abs=1e-4)

    for position in (0.05, -0.001):   # 100 mm > max_width, below 0
        answer = gripper.gripper_command(position, 20.0)
        assert answer.status == ABORTED
        assert (answer.result.position, answer.result.reached_goal) == (0.0, False)
    assert gripper.width_m() == pytest.approx(0.06, abs=0.002)    # nothing moved


def test_gripper_action_grasps_with_max_effort_and_never_reports_stalled(executor, client, spin):
    """Closing onto the 50 mm box at its width grasps it with max_effort as the force: reached_goal, the width in
    `position`; effort 0 and stalled false. Closing to 0 onto the box stops on it, outside the 5 mm band: aborted
    with stalled still false (franka_gripper fills neither effort nor stalled)."""
    driver = _driver(executor)
    gripper = Gripper(executor, client, spin)
    box_width_m = _over_the_box(driver, executor, spin)

    answer = gripper.gripper_command(box_width_m / 2, 40.0)
    assert answer.status == SUCCEEDED
    r = answer.result
    assert r.reached_goal and (r.stalled, r.effort) == (False, 0.0), r
    assert r.position == pytest.approx(box_width_m, abs=0.004)
    assert sum(_pad_forces_n(driver)) / 2 == pytest.approx(40.0, rel=0.1)   # max_effort is the grasp force

    answer = gripper.gripper_command(0.0, 15.0)
    assert answer.status == ABORTED
    r = answer.result
    assert (r.reached_goal, r.stalled, r.effort) == (False, False, 0.0), r
    assert r.position == pytest.approx(box_width_m, abs=0.004)


def test_stop_aborts_the_running_move_grasp_and_gripper_command_goals(executor, client, spin, call):
    """`stop` (Gripper::stop) answers success with no message; the goal whose command it ends is aborted by its own
    action (not canceled): Move and Grasp with success false, GripperCommand with reached_goal false and the width
    it stopped at; the fingers stop where they are."""
    from control_msgs.action import GripperCommand
    from control_msgs.msg import GripperCommand as Command
    from franka_msgs.action import Grasp, Move
    from franka_msgs.msg import GraspEpsilon

    _driver(executor, real_time=True)
    gripper = Gripper(executor, client, spin)
    response = gripper.call_stop(call)   # nothing running: still success
    assert (response.success, response.message) == (True, "")

    def stopped_while_running(action, goal):
        assert gripper.result(gripper.send(gripper.move, Move.Goal(width=0.08, speed=0.1))).result.success
        feedback = []
        handle = gripper.send(action, goal, feedback=feedback.append)
        spin(executor, lambda: feedback, TIMEOUT_S, "feedback of the running goal")
        response = gripper.call_stop(call)
        assert (response.success, response.message) == (True, "")
        answer = gripper.result(handle)
        assert answer.status == ABORTED, answer
        return answer.result

    r = stopped_while_running(gripper.move, Move.Goal(width=0.0, speed=0.02))
    assert not r.success
    r = stopped_while_running(gripper.grasp, Grasp.Goal(width=0.0, epsilon=GraspEpsilon(inner=0.005, outer=0.005),
                                                        speed=0.02, force=20.0))
    assert not r.success
    # GripperCommand closes at franka_gripper's default 0.1 m/s: 0.8 s (sim, here paced to wall time) to close
    r = stopped_while_running(gripper.command, GripperCommand.Goal(command=Command(position=0.0, max_effort=20.0)))
    assert (r.reached_goal, r.stalled, r.effort) == (False, False, 0.0) and 0.005 < r.position < 0.079, r
    seen = len(gripper.fingers)
    spin(executor, lambda: len(gripper.fingers) >= seen + 5, TIMEOUT_S, "finger states after the stop")
    assert gripper.width_m() == pytest.approx(r.position, abs=0.003)   # stopped there, not closing on


def test_gripper_action_and_stop_resolve_in_the_drivers_namespace(executor, client, spin, call):
    """franka_gripper's `~/gripper_action` and `~/stop` of node `franka_gripper` in the launch's namespace: under
    `left` they are /left/franka_gripper/gripper_action (control_msgs/action/GripperCommand) and
    /left/franka_gripper/stop (std_srvs/srv/Trigger), and work there."""
    from rclpy.action import get_action_server_names_and_types_by_node

    driver = _driver(executor, namespace="left")
    gripper = Gripper(executor, client, spin, prefix="/left/")
    actions = dict(get_action_server_names_and_types_by_node(client, driver.get_name(), "/left"))
    assert actions["/left/franka_gripper/gripper_action"] == ["control_msgs/action/GripperCommand"]
    services = dict(client.get_service_names_and_types_by_node(driver.get_name(), "/left"))
    assert services["/left/franka_gripper/stop"] == ["std_srvs/srv/Trigger"]
    answer = gripper.gripper_command(0.02, 20.0)     # 80 -> 40 mm on nothing: a grasp that closes fully
    assert answer.status == ABORTED and answer.result.position < 0.01
    answer = gripper.gripper_command(0.02, 20.0)     # 0 -> 40 mm: a move
    assert answer.status == SUCCEEDED and answer.result.position == pytest.approx(0.04, abs=0.002)
    assert gripper.call_stop(call).success
