"""The one client of the running cell: PlanGrasp, SetStiffness and PickAndPlace as blocking calls.

Two ways to wait, one set of calls and one error type (CellCallError):
- the node is spun by an executor in another thread (sessions: record, replay): give no `spin_until`;
  the calls wait on their futures;
- the caller spins the node itself (the demo, tests): give `spin_until(predicate, timeout_s) -> bool`,
  which spins until predicate() holds. Spinning where the request is sent avoids rclpy's race in which
  an action goal response that arrives before the client registered the request is dropped.

When a recorder is given (defgg_ros/sessions/recorder_node.py), every request/response and
goal/feedback/result is handed to it, so a session bag holds the calls.
"""
import threading
import time

from defgg_interfaces.action import PickAndPlace
from defgg_interfaces.srv import Perceive, PlanGrasp, SetStiffness
from franka_msgs.action import Grasp

from defgg_ros.ros import topics
from defgg_ros.ros.action import ActionClient, ResultTimeout, result_of_goal
from defgg_ros.ros.service import ServiceTimeout, call_idempotent

POLL_S = 0.05          # how often a wait without our own spinning re-checks a condition
GOAL_RESPONSE_TIMEOUT_S = 30.0


class CellCallError(RuntimeError):
    """A call into the cell that did not complete (server missing, timeout, refused request, rejected goal)."""


def wait_future(future, timeout_s: float, what: str):
    """The result of a future completed by an executor in another thread; CellCallError after timeout_s."""
    done = threading.Event()
    future.add_done_callback(lambda _: done.set())
    if not done.wait(timeout_s):
        future.cancel()
        raise CellCallError(f"{what}: no answer within {timeout_s:g} s")
    if future.exception() is not None:
        raise CellCallError(f"{what}: {future.exception()!r}")
    return future.result()


class CellClient:
    def __init__(self, node, recorder=None, spin_until=None):
        self.node = node
        self.recorder = recorder
        self._spin_until = spin_until
        self.plan_client = node.create_client(PlanGrasp, topics.PLAN_GRASP_SERVICE)
        self.perceive_client = node.create_client(Perceive, topics.PERCEIVE_SERVICE)
        self.stiffness_client = node.create_client(SetStiffness, topics.SET_STIFFNESS_SERVICE)
        self.pick_client = ActionClient(node, PickAndPlace, topics.PICK_AND_PLACE_ACTION)
        self.gripper_client = ActionClient(node, Grasp, topics.GRIPPER_GRASP_ACTION)

    # ---- waiting -------------------------------------------------------------
    def wait_until(self, predicate, timeout_s: float) -> bool:
        """True once predicate() holds, False after timeout_s (spinning the node if this client spins it)."""
        if self._spin_until is not None:
            return self._spin_until(predicate, timeout_s)
        deadline = time.monotonic() + timeout_s
        while not predicate():
            if time.monotonic() >= deadline:
                return False
            time.sleep(POLL_S)
        return True

    def wait(self, predicate, timeout_s: float, what: str) -> None:
        if not self.wait_until(predicate, timeout_s):
            raise CellCallError(f"timed out after {timeout_s:g} s waiting for {what}")

    def result_of(self, future, timeout_s: float, what: str):
        if self._spin_until is None:
            return wait_future(future, timeout_s, what)
        self.wait(future.done, timeout_s, what)
        if future.exception() is not None:
            raise CellCallError(f"{what}: {future.exception()!r}")
        return future.result()

    def wait_for_servers(self, timeout_s: float, pick: bool, alive=lambda: None) -> None:
        """Wait until the services (and the pick action) exist; `alive()` raises if a process died."""
        deadline = time.monotonic() + timeout_s
        waits = [(self.plan_client.service_is_ready, topics.PLAN_GRASP_SERVICE, False),
                 (self.stiffness_client.service_is_ready, topics.SET_STIFFNESS_SERVICE, False)]
        if pick:
            # The driver loads its scene slower than the executor starts: wait for its gripper action too.
            waits += [(self.gripper_client.server_is_ready, topics.GRIPPER_GRASP_ACTION, True),
                      (self.pick_client.server_is_ready, topics.PICK_AND_PLACE_ACTION, True)]
        for ready, name, action in waits:
            while not self.wait_until(ready, 0.5):
                alive()
                if time.monotonic() > deadline:
                    raise CellCallError(f"{name} did not appear within {timeout_s:g} s; "
                                        f"{self._graph_says(name, action)}")

    def _graph_says(self, name: str, action: bool) -> str:
        """What this node's graph shows of the cell: whether a server of that name is known (then discovery saw it
        but its endpoints did not match) and which nodes it sees (none: another ROS domain, or no discovery)."""
        resolved = self.node.resolve_service_name(name)
        servers = self.node.count_services(f"{resolved}/_action/send_goal" if action else resolved)
        nodes = sorted(f"{ns.rstrip('/')}/{n}" for n, ns in self.node.get_node_names_and_namespaces())
        known = (f"the graph lists {servers} server(s) of {resolved} (not matched with this client yet)" if servers
                 else f"the graph lists no server of {resolved}")
        return f"{known}; {len(nodes)} node(s) seen: {', '.join(nodes[:12]) or 'none'}"

    # ---- calls ---------------------------------------------------------------
    def _call(self, client, request, timeout_s: float, what: str):
        """An idempotent service call, re-sent while unanswered (defgg_ros/ros/service.py)."""
        self.wait(client.service_is_ready, timeout_s, f"the {what} service")
        try:
            return call_idempotent(client, request, timeout_s, what, wait_until=self._spin_until)
        except (ServiceTimeout, RuntimeError) as error:
            raise CellCallError(str(error)) from None

    def plan(self, request, timeout_s: float = 30.0):
        """PlanGrasp; the response (success false with a message is an answer, not an error)."""
        sent_ns = time.time_ns()
        response = self._call(self.plan_client, request, timeout_s, "PlanGrasp")
        if self.recorder is not None:
            self.recorder.record_plan(request, response, sent_ns)
        return response

    def perceive(self, depth, camera_info, objects=(), timeout_s: float = 30.0):
        """The segmentation node's Perceive of a frame this client holds; the response (success false with a
        message is an answer, not an error)."""
        request = Perceive.Request(depth=depth, camera_info=camera_info, objects=list(objects))
        return self._call(self.perceive_client, request, timeout_s, "Perceive")

    def set_stiffness(self, objects, default_youngs_modulus_pa: float = 0.0, timeout_s: float = 10.0):
        """SetStiffness; CellCallError if the segmentation node refuses the assignments."""
        request = SetStiffness.Request(objects=list(objects),
                                       default_youngs_modulus_pa=float(default_youngs_modulus_pa))
        response = self._call(self.stiffness_client, request, timeout_s, "SetStiffness")
        if not response.success:
            raise CellCallError(f"SetStiffness refused the assignments: {response.message}")
        return response

    def pick(self, goal, on_feedback=None, timeout_s: float = 300.0):
        """Send a PickAndPlace goal and wait for its result (PickAndPlace.Result); a goal still running
        at the timeout is cancelled."""
        self.wait(self.pick_client.server_is_ready, GOAL_RESPONSE_TIMEOUT_S, "the PickAndPlace action server")
        sent_ns = time.time_ns()
        if self.recorder is not None:
            self.recorder.record_pick_goal(goal, sent_ns)

        def feedback_callback(message):
            if self.recorder is not None:
                self.recorder.record_pick_feedback(message.feedback)
            if on_feedback is not None:
                on_feedback(message.feedback)

        handle = self.result_of(self.pick_client.send_goal_async(goal, feedback_callback=feedback_callback),
                                GOAL_RESPONSE_TIMEOUT_S, "the PickAndPlace goal response")
        if not handle.accepted:
            raise CellCallError("the executor rejected the PickAndPlace goal (busy?)")
        try:
            result = result_of_goal(handle, timeout_s, "the PickAndPlace result", self.wait_until).result
        except (ResultTimeout, RuntimeError) as exc:
            handle.cancel_goal_async()
            raise CellCallError(str(exc)) from None
        if self.recorder is not None:
            self.recorder.record_pick_result(result)
        return result
