"""Shared test set-up: ROS isolation per test process, rclpy fixtures, waits.

Each pytest process gets its own ROS_DOMAIN_ID and localhost-only discovery
so parallel runs (and a cell running on the same machine) never cross-talk.
"""
import os
import random
import time

import pytest

# Must happen before rclpy initialises its context.
os.environ["ROS_DOMAIN_ID"] = str(random.Random(os.getpid()).randint(1, 100))
os.environ["ROS_AUTOMATIC_DISCOVERY_RANGE"] = "LOCALHOST"


@pytest.fixture
def rclpy_context():
    """An initialised rclpy context, shut down after the test."""
    import rclpy
    from rclpy.context import Context

    context = Context()
    rclpy.init(context=context)
    try:
        yield context
    finally:
        context.try_shutdown()


@pytest.fixture
def executor(rclpy_context):
    """A ThreadedExecutor (defgg_ros.ros_executor) on the test's context; nodes added to it are destroyed after."""
    from defgg_ros.ros_executor import ThreadedExecutor

    ex = ThreadedExecutor(num_threads=4, context=rclpy_context)
    yield ex
    from defgg_ros.ros_action import destroy_actions

    for node in list(ex.get_nodes()):
        ex.remove_node(node)
        destroy_actions(node)  # plain client nodes too: rclpy's destroy_node leaves actions alive
        node.destroy_node()
    ex.shutdown(timeout_sec=2.0)


@pytest.fixture
def inference_service(executor):
    """Factory: start a GraspInferenceNode on `executor` with these parameters, plus a client node whose
    PlanGrasp client is ready. Returns (inference node, client node, client)."""
    from defgg_interfaces.srv import PlanGrasp
    from rclpy.node import Node
    from rclpy.parameter import Parameter

    from defgg_ros import topics
    from defgg_ros.nodes.grasp_inference_node import GraspInferenceNode

    def start(client_name: str, **parameters):
        node = GraspInferenceNode(context=executor.context, parameter_overrides=[
            Parameter(name, value=value) for name, value in parameters.items()])
        executor.add_node(node)
        client_node = Node(client_name, context=executor.context)
        executor.add_node(client_node)
        service = parameters.get("plan_grasp_service", topics.PLAN_GRASP_SERVICE)
        client = client_node.create_client(PlanGrasp, service)
        assert client.wait_for_service(timeout_sec=10.0), f"{service} did not appear"
        return node, client_node, client

    return start


def spin_until(executor, done, timeout_s: float, what: str):
    """Spin `executor` until `done` (a Future or a callable -> bool) is true.

    Fails the test with `what` after `timeout_s` seconds; never sleeps.
    Returns the future's result when `done` is a Future.
    """
    is_future = hasattr(done, "done") and hasattr(done, "result")
    if not _spin_while_not(executor, done.done if is_future else done, timeout_s):
        pytest.fail(f"timed out after {timeout_s:.1f} s waiting for {what}")
    return done.result() if is_future else True


def _spin_while_not(executor, check, timeout_s: float) -> bool:
    """Spin `executor` in short slices until check() holds (True) or `timeout_s` passes (False)."""
    deadline = time.monotonic() + timeout_s
    while not check():
        remaining = deadline - time.monotonic()
        if remaining <= 0:
            return False
        executor.spin_once(timeout_sec=min(0.05, remaining))
    return True


@pytest.fixture
def spin():
    """The spin_until helper as a fixture: spin(executor, done, timeout_s, what)."""
    return spin_until


def call_service(executor, client, request, timeout_s: float, what: str):
    """Call `client` with an idempotent `request`, spinning `executor` here and re-sending it while
    unanswered (defgg_ros.ros_service: Fast DDS can drop a response to a just-started client).
    Fails the test with `what` after `timeout_s`; returns the response."""
    from defgg_ros.ros_service import ServiceTimeout, call_idempotent

    def wait_until(predicate, wait_s):
        return _spin_while_not(executor, predicate, wait_s)

    try:
        return call_idempotent(client, request, timeout_s, what, wait_until=wait_until)
    except ServiceTimeout as error:
        pytest.fail(str(error))


@pytest.fixture
def call():
    """The call_service helper as a fixture: call(executor, client, request, timeout_s, what)."""
    return call_service
