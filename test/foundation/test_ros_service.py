"""call_idempotent re-sends a request that was lost on real DDS (defgg_ros/ros/service.py)."""
import threading
import time

import pytest
from std_srvs.srv import Trigger

from defgg_ros.ros.service import ServiceTimeout, call_idempotent


class LateServer:
    """Spins `executor` for call_idempotent; the Trigger server starts only after the first send,
    so that send goes to nobody and is lost (volatile DDS request, no reader yet)."""

    def __init__(self, executor, service_name):
        self.executor, self.service_name = executor, service_name
        self.node = None
        self.requests = 0

    def _handle(self, _request, response):
        self.requests += 1
        response.success, response.message = True, f"answer {self.requests}"
        return response

    def wait_until(self, predicate, timeout_s) -> bool:
        if self.node is None:
            from rclpy.node import Node

            self.node = Node("late_trigger_server", context=self.executor.context)
            self.node.create_service(Trigger, self.service_name, self._handle)
            self.executor.add_node(self.node)
        deadline = time.monotonic() + timeout_s
        while not predicate() and time.monotonic() < deadline:
            self.executor.spin_once(timeout_sec=0.05)
        return predicate()


def _client(executor, name):
    from rclpy.node import Node

    node = Node(name, context=executor.context)
    executor.add_node(node)
    return node.create_client(Trigger, "late_trigger")


def test_a_request_lost_before_the_server_existed_is_answered_after_a_resend(executor):
    client = _client(executor, "resending_client")
    server = LateServer(executor, "late_trigger")
    response = call_idempotent(client, Trigger.Request(), 20.0, "late trigger", resend_every_s=1.0,
                               wait_until=server.wait_until)
    assert response.success and response.message == "answer 1"
    assert server.requests == 1  # the first send never reached it


def test_without_a_resend_the_lost_request_times_out(executor):
    client = _client(executor, "patient_client")
    server = LateServer(executor, "late_trigger")
    with pytest.raises(ServiceTimeout, match="no answer within 3 s"):
        call_idempotent(client, Trigger.Request(), 3.0, "late trigger", resend_every_s=10.0,
                        wait_until=server.wait_until)
    assert server.requests == 0


def test_with_an_executor_in_another_thread_one_send_is_answered(executor):
    from rclpy.node import Node

    calls = []

    def handle(_request, response):
        calls.append(1)
        response.success = True
        return response

    server = Node("trigger_server", context=executor.context)
    server.create_service(Trigger, "counted_trigger", handle)
    executor.add_node(server)
    client_node = Node("threaded_client", context=executor.context)
    executor.add_node(client_node)
    client = client_node.create_client(Trigger, "counted_trigger")
    spinner = threading.Thread(target=executor.spin, daemon=True)
    spinner.start()
    assert client.wait_for_service(timeout_sec=10.0)
    response = call_idempotent(client, Trigger.Request(), 20.0, "counted trigger")
    assert response.success
    assert len(calls) == 1


def test_a_non_positive_resend_period_is_refused(executor):
    with pytest.raises(ValueError, match="resend_every_s"):
        call_idempotent(_client(executor, "bad_period_client"), Trigger.Request(), 1.0, "x", resend_every_s=0)
