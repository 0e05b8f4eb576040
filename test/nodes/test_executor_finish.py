"""Ending goals: a failure after a success in the same process keeps its reason.

rclpy refuses to change a logging call site's severity between calls; one
shared call site for info/warning made the second goal's result vanish.
"""
from defgg_interfaces.action import PickAndPlace

from defgg_ros.control.sequence_types import Outcome
from defgg_ros.nodes.executor_node import ExecutorNode


class _GoalHandle:
    """Records how the goal was ended (the server side of one goal)."""

    def __init__(self):
        self.ended = None

    def succeed(self):
        self.ended = "succeeded"

    def abort(self):
        self.ended = "aborted"

    def canceled(self):
        self.ended = "canceled"


def test_success_then_failure_then_cancel_all_report(rclpy_context):
    node = ExecutorNode(context=rclpy_context)
    try:
        outcomes = [
            (Outcome(success=True, phase_reached="done", duration_s=3.0), "succeeded"),
            (Outcome(failure_reason="missed: fingers closed to 0.0 mm", phase_reached="close"), "aborted"),
            (Outcome(canceled=True, failure_reason="canceled", phase_reached="descend"), "canceled"),
            (Outcome(success=True, phase_reached="done"), "succeeded"),
        ]
        for outcome, expected in outcomes:
            handle = _GoalHandle()
            result = node._finish(handle, outcome, PickAndPlace.Result())
            assert handle.ended == expected
            assert result.failure_reason == outcome.failure_reason
            assert result.success == outcome.success
    finally:
        node.destroy_node()
