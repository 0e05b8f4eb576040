"""Blocking calls into the cell (PlanGrasp, SetStiffness, PickAndPlace) that can be recorded.

Used from a plain thread while an executor spins the node in another
thread. When a SessionRecorder is given, every request/response and goal/
feedback/result is written into the session bag.
"""
import threading
import time

from defgg_interfaces.action import PickAndPlace
from defgg_interfaces.srv import PlanGrasp, SetStiffness
from franka_msgs.action import Grasp

from defgg_ros.ros.action import ActionClient
from defgg_ros.ros.service import ServiceTimeout, call_idempotent
from defgg_ros.sessions.session_topics import topics  # absolute names (bag channels)


class CellCallError(RuntimeError):
    """A call into the cell that did not complete (server missing, timeout, rejected goal)."""


def wait_future(future, timeout_s: float, what: str):
    done = threading.Event()
    future.add_done_callback(lambda _: done.set())
    if not done.wait(timeout_s):
        future.cancel()
        raise CellCallError(f"{what}: no answer within {timeout_s:g} s")
    if future.exception() is not None:
        raise CellCallError(f"{what}: {future.exception()!r}")
    return future.result()


def _call(client, request, timeout_s: float, what: str):
    """An idempotent service call (re-sent while unanswered: defgg_ros/ros/service.py)."""
    try:
        return call_idempotent(client, request, timeout_s, what)
    except (ServiceTimeout, RuntimeError) as error:
        raise CellCallError(str(error)) from None


class CellClient:
    def __init__(self, node, recorder=None):
        self.node = node
        self.recorder = recorder
        self.plan_client = node.create_client(PlanGrasp, topics.PLAN_GRASP_SERVICE)
        self.stiffness_client = node.create_client(SetStiffness, topics.SET_STIFFNESS_SERVICE)
        self.pick_client = ActionClient(node, PickAndPlace, topics.PICK_AND_PLACE_ACTION)
        self.gripper_client = ActionClient(node, Grasp, topics.GRIPPER_GRASP_ACTION)

    def wait_for_servers(self, timeout_s: float, pick: bool, alive=lambda: None) -> None:
        """Wait until the services (and the pick action) exist; `alive()` raises if a process died."""
        deadline = time.monotonic() + timeout_s
        waits = [(self.plan_client.wait_for_service, topics.PLAN_GRASP_SERVICE),
                 (self.stiffness_client.wait_for_service, topics.SET_STIFFNESS_SERVICE)]
        if pick:
            # The driver loads its scene slower than the executor starts: wait for its gripper action too.
            waits += [(self.gripper_client.wait_for_server, topics.GRIPPER_GRASP_ACTION),
                      (self.pick_client.wait_for_server, topics.PICK_AND_PLACE_ACTION)]
        for wait, name in waits:
            while not wait(timeout_sec=0.5):
                alive()
                if time.monotonic() > deadline:
                    raise CellCallError(f"{name} did not appear within {timeout_s:g} s")

    def plan(self, request, timeout_s: float = 30.0):
        sent_ns = time.time_ns()
        response = _call(self.plan_client, request, timeout_s, "PlanGrasp")
        if self.recorder is not None:
            self.recorder.record_plan(request, response, sent_ns)
        return response

    def set_stiffness(self, objects, default_youngs_modulus_pa: float, timeout_s: float = 10.0):
        request = SetStiffness.Request(objects=list(objects),
                                       default_youngs_modulus_pa=float(default_youngs_modulus_pa))
        response = _call(self.stiffness_client, request, timeout_s, "SetStiffness")
        if not response.success:
            raise CellCallError(f"SetStiffness refused the assignments: {response.message}")
        return response

    def pick(self, goal, timeout_s: float = 300.0, on_feedback=None):
        sent_ns = time.time_ns()
        if self.recorder is not None:
            self.recorder.record_pick_goal(goal, sent_ns)

        def feedback_callback(message):
            if self.recorder is not None:
                self.recorder.record_pick_feedback(message.feedback)
            if on_feedback is not None:
                on_feedback(message.feedback)

        handle = wait_future(self.pick_client.send_goal_async(goal, feedback_callback=feedback_callback),
                             10.0, "PickAndPlace goal")
        if not handle.accepted:
            raise CellCallError("the executor rejected the PickAndPlace goal (busy?)")
        result = wait_future(handle.get_result_async(), timeout_s, "PickAndPlace result").result
        if self.recorder is not None:
            self.recorder.record_pick_result(result)
        return result
