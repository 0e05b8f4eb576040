"""The executor's gripper commands over real DDS: a cancel that comes before the gripper accepted its goal.

A franka_msgs Grasp server (real rclpy ActionServer) that takes its time to accept, the executor's ArmCommands
sending a grasp and then, before the acceptance, the sequence's CancelGripper. The cancel must reach that goal once
it is accepted; it canceled the previous (finished) goal's handle instead and the grasp closed to its end.
"""
import threading

import pytest
from franka_msgs.action import Grasp, Move
from rclpy.action import ActionServer, CancelResponse, GoalResponse
from rclpy.node import Node

from defgg_ros.control.gripper_rule import GraspCommand
from defgg_ros.control.sequence_types import CancelGripper, GraspGripper
from defgg_ros.nodes.executor_arm import ArmCommands
from defgg_ros.ros.action import ActionClient

pytestmark = pytest.mark.ros
TIMEOUT_S = 20.0


class _Commands(Node, ArmCommands):
    """ArmCommands with the state the executor node gives it, and nothing else."""

    def __init__(self, context):
        super().__init__("gripper_cancel_probe", context=context)
        self._lock = threading.RLock()
        self._sequence = object()
        self._gripper_goal = None
        self._gripper_serial = self._gripper_canceled_serial = 0
        self._gripper_feedback_width_m = float("nan")
        self._move_client = ActionClient(self, Move, "probe_gripper/move")
        self._grasp_client = ActionClient(self, Grasp, "probe_gripper/grasp")

    def _gripper_width_m(self) -> float:
        return 0.05


def test_a_cancel_before_the_grippers_acceptance_reaches_the_goal(executor, rclpy_context, spin):
    accept = threading.Event()
    seen = {"canceled": False, "ended": None}
    server_node = Node("slow_gripper", context=rclpy_context)

    def on_goal(_request):
        accept.wait(TIMEOUT_S)        # the gripper is slow to accept (a busy machine, a slow network)
        return GoalResponse.ACCEPT

    def on_cancel(_handle):
        seen["canceled"] = True
        return CancelResponse.ACCEPT

    def execute(handle):
        for _ in range(200):           # closes for up to 2 s unless canceled
            if handle.is_cancel_requested:
                handle.canceled()
                seen["ended"] = "canceled"
                return Grasp.Result(success=False, error="canceled")
            threading.Event().wait(0.01)
        handle.succeed()
        seen["ended"] = "succeeded"
        return Grasp.Result(success=True)

    server = ActionServer(server_node, Grasp, "probe_gripper/grasp", execute, goal_callback=on_goal,
                          cancel_callback=on_cancel)
    commands = _Commands(rclpy_context)
    for node in (server_node, commands):
        executor.add_node(node)
    spin(executor, commands._grasp_client.server_is_ready, TIMEOUT_S, "the grasp server")
    grasp = GraspCommand(pre_open_width_m=0.08, width_m=0.05, epsilon_inner_m=0.005, epsilon_outer_m=0.005,
                         speed_mps=0.02, force_n=5.0)
    with commands._lock:
        commands._carry_out(commands._sequence, [GraspGripper(grasp)])
        commands._carry_out(commands._sequence, [CancelGripper()])     # before the goal is accepted
    accept.set()
    spin(executor, lambda: seen["ended"] is not None, TIMEOUT_S, "the grasp goal's end")
    assert seen["canceled"] and seen["ended"] == "canceled"
    for node in (server_node, commands):
        executor.remove_node(node)
    server.destroy()
