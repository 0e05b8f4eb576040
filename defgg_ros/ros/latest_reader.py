"""The newest message of a fast topic, taken when its owner wants it instead of handed to a callback.

franka_robot_state_broadcaster publishes the external wrench at 1 kHz (docs/franka_contract.md). Read by a
subscription callback, every message costs an rclpy executor a whole pass of its wait loop: the executor node,
idle beside the simulated driver, used 0.69 of a core (0.23 with this reader), and a one-subscription node spun by
rclpy's SingleThreadedExecutor 0.44 of a core for 651 messages/s; the same reader taken 100 times a second used
0.06 (bench/bench_wrench_read.py). The executor needs only the newest wrench, at its control ticks (100 Hz).

So the subscription lives on a hidden node of its own that no executor spins: DDS keeps the newest message in the
reader's queue (best effort, depth 1, replaced in the middleware's threads), and `take` returns it with its age.
The take is rclpy's own (`Subscription.handle.take_message`, what its executors and `wait_for_message` call);
rclpy 7 (Jazzy) has no public call for it.
"""
import threading
import time

from rclpy.node import Node
from rclpy.parameter import Parameter


class LatestMessageReader:
    """Reads `topic` (resolved by `owner`: its namespace and remappings) on a hidden node named
    `_<owner>_<purpose>`; `take()` gives the newest message received since the last take."""

    def __init__(self, owner: Node, msg_type, topic: str, qos_profile, purpose: str):
        self.topic = owner.resolve_topic_name(topic)
        # Global arguments stay with the owner: a `__node:=` rename would give this node the owner's name, and the
        # topic is already remapped.
        self._node = Node(f"_{owner.get_name()}_{purpose}", namespace=owner.get_namespace(), context=owner.context,
                          use_global_arguments=False, start_parameter_services=False, enable_rosout=False,
                          parameter_overrides=[Parameter("start_type_description_service", value=False)])
        self._subscription = self._node.create_subscription(msg_type, self.topic, _never_called, qos_profile)
        self._lock = threading.Lock()   # one take at a time: the owner's control loop and its timers both read

    def take(self):
        """(message, age_s) of the newest message received since the last take, else None. The age comes from the
        middleware's reception time (system clock); 0.0 when it gives none."""
        with self._lock, self._subscription.handle:
            taken = self._subscription.handle.take_message(self._subscription.msg_type, False)
        if taken is None:
            return None
        msg, info = taken
        received_ns = int(info.get("received_timestamp") or 0)
        age_s = max(0.0, (time.time_ns() - received_ns) * 1e-9) if received_ns > 0 else 0.0
        return msg, age_s

    def destroy(self) -> None:
        self._node.destroy_node()


def _never_called(_msg) -> None:
    """The subscription's callback: its node is never spun, its messages are taken."""
