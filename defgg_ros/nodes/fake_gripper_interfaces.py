"""franka_gripper's `gripper_action` (control_msgs/GripperCommand) and `stop` (std_srvs/Trigger) on the fake driver.

What franka_ros2 3.4.0's franka_gripper does (`franka_gripper/src/gripper_action_server.cpp`, onExecuteGripperCommand,
executeGripperCommand, stopServiceCallback; docs/franka_contract.md, "The gripper's GripperCommand and stop"):

- The target width is twice `command.position` (a finger's travel). Outside [0, max_width] the goal is aborted
  with an empty result (position 0.0). Within SAME_POSITION_M of the current width it succeeds at once
  (reached_goal, position = the width). Otherwise opening (target >= width) is `Gripper::move(target, default_speed)`
  and closing is `Gripper::grasp(target, default_speed, max_effort, default epsilons)`: max_effort is the grasp force
  in N and nothing else; there is no effort threshold.
- The result: reached_goal = what move()/grasp() returned (false on a libfranka exception), position = the width
  (the whole opening, not a finger's), effort 0.0 and stalled false always; succeeded when reached_goal, else
  aborted. A closing command on an object wider than target + 5 mm is a grasp outside its band: aborted.
- Feedback at feedback_publish_rate (30 Hz in franka_gripper_node.yaml): position = the width, the rest 0/false.
- Cancel: Gripper::stop(), the goal ends canceled with the command's result (position, effort left at 0.0).
- `stop`: Gripper::stop(); success = its return, message = a libfranka exception's text (""). It cancels no goal
  itself: the running command (Move, Grasp, Homing or GripperCommand) returns unsuccessful and its goal is
  aborted by its own executor; a held grasp lets go of its force.

The simulated hand does these with the driver's gripper machinery (SimCell.gripper_move/grasp/stop, the driver's
waiters finished by its sim thread): see `serve_gripper_interfaces`.
"""
import threading

from control_msgs.action import GripperCommand
from rclpy.action import ActionServer, CancelResponse, GoalResponse
from std_srvs.srv import Trigger

from defgg_ros.constants import GRIPPER_MAX_WIDTH_M
from defgg_ros.sim.cell.gripper import GripperCommandError

DEFAULT_SPEED_MPS = 0.1          # franka_gripper_node.yaml's default_speed
DEFAULT_EPSILON_M = 0.005        # default_grasp_epsilon.inner and .outer
SAME_POSITION_M = 1e-4           # kSamePositionThreshold: already there, succeed without a command
FEEDBACK_RATE_HZ = 30.0          # feedback_publish_rate (wall clock, like franka_gripper's wait)


def serve_gripper_interfaces(driver, callback_group) -> None:
    """Create the `gripper_action` server and the `stop` service on the fake driver (names from its parameters
    gripper_command_action and gripper_stop_service)."""
    interfaces = _GripperInterfaces(driver)
    ActionServer(driver, GripperCommand, driver.cfg["gripper_command_action"], execute_callback=interfaces.execute,
                 callback_group=callback_group, goal_callback=lambda _goal: GoalResponse.ACCEPT,
                 cancel_callback=lambda _goal: CancelResponse.ACCEPT)
    driver.create_service(Trigger, driver.cfg["gripper_stop_service"], interfaces.on_stop,
                          callback_group=callback_group)


class _GripperInterfaces:
    def __init__(self, driver):
        self.driver = driver

    def on_stop(self, _request, response):
        """Gripper::stop(): the running command ends unsuccessful (its goal, whichever action started it, is aborted
        when the sim thread reports it) and the fingers hold no force."""
        with self.driver._lock:
            self.driver.cell.gripper_stop()
        response.success, response.message = True, ""
        self.driver.get_logger().info("gripper stopped (stop service)")
        return response

    def execute(self, goal_handle):
        driver, command = self.driver, goal_handle.request.command
        target_m = 2.0 * command.position
        with driver._lock:
            width_m = driver.cell.gripper_width_m()
        if not 0.0 <= target_m <= GRIPPER_MAX_WIDTH_M:
            driver.get_logger().error(f"GripperCommand: width {target_m} m (2 x position) outside "
                                      f"[0, {GRIPPER_MAX_WIDTH_M}] m")
            goal_handle.abort()
            return GripperCommand.Result()
        if abs(target_m - width_m) < SAME_POSITION_M:
            goal_handle.succeed()
            return GripperCommand.Result(position=width_m, reached_goal=True)
        cell = driver.cell
        if target_m >= width_m:
            def start():
                return cell.gripper_move(target_m, DEFAULT_SPEED_MPS)
        else:
            def start():
                return cell.gripper_grasp(target_m, DEFAULT_EPSILON_M, DEFAULT_EPSILON_M, DEFAULT_SPEED_MPS,
                                          float(command.max_effort))
        reached = self._run(goal_handle, start)
        if reached is None:   # canceled (or the driver shutting down): the command's result, nothing filled in
            if goal_handle.is_cancel_requested:
                goal_handle.canceled()
            else:
                goal_handle.abort()
            return GripperCommand.Result()
        with driver._lock:
            result = GripperCommand.Result(position=cell.gripper_width_m(), reached_goal=reached)
        if reached:
            goal_handle.succeed()
        else:
            goal_handle.abort()
        return result

    def _run(self, goal_handle, start):
        """Run one simulated gripper command to its end: True/False (what libfranka's move/grasp returned), None
        when the goal was canceled (Gripper::stop)."""
        driver = self.driver
        try:
            with driver._lock:
                token = start()
                waiter = driver._waiters[token] = [threading.Event(), None]
        except GripperCommandError as exc:   # libfranka would throw: reached_goal false
            driver.get_logger().error(f"GripperCommand: {exc}")
            return False
        while not waiter[0].wait(1.0 / FEEDBACK_RATE_HZ):
            if goal_handle.is_cancel_requested or not driver._running:
                with driver._lock:
                    driver.cell.gripper_stop()
                    driver._waiters.pop(token, None)
                return None
            with driver._lock:
                width_m = driver.cell.gripper_width_m()
            goal_handle.publish_feedback(GripperCommand.Feedback(position=width_m))
        outcome = waiter[1]
        if not outcome.success:
            driver.get_logger().info(f"GripperCommand failed: {outcome.error}")
        return outcome.success
