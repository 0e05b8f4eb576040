"""Is a node ready? Ask the ROS graph from a small probe node (its own rclpy context)."""
import time

import rclpy
from rclpy.context import Context
from rclpy.executors import SingleThreadedExecutor
from rclpy.node import Node, NodeNameNonExistentError

from defgg_ros.bringup.node_set import ReadyCheck

# Graph queries are cheap; spinning the probe between them lets discovery progress.
PROBE_SPIN_S = 0.1
# How long a fresh probe listens before it trusts that a node is absent (discovery on one host takes
# < 1 s when idle; 2 s missed a node on the loaded 2-core machine).
DISCOVERY_WAIT_S = 5.0


class ReadinessProbe:
    def __init__(self):
        self._context = Context()
        rclpy.init(context=self._context)
        self.node = Node("defgg_bringup_probe", context=self._context)
        self._executor = SingleThreadedExecutor(context=self._context)
        self._executor.add_node(self.node)

    def is_ready(self, check: ReadyCheck, node_name: str, namespace: str = "/") -> bool:
        """Does the node called node_name offer the checked interface?

        Asking per node (not the whole graph) keeps another process that
        offers the same name in the same ROS domain from passing for it.
        """
        if node_name not in self.node.get_node_names():
            return False
        try:
            if check.kind == "topic":
                topics = self.node.get_publisher_names_and_types_by_node(node_name, namespace)
                return check.name in {name for name, _ in topics}
            services = {name for name, _ in self.node.get_service_names_and_types_by_node(node_name, namespace)}
        except NodeNameNonExistentError:  # it went away between the two queries
            return False
        if check.kind == "service":
            return check.name in services
        return f"{check.name}/_action/send_goal" in services

    def nodes_present(self, names, discovery_s: float = DISCOVERY_WAIT_S) -> list:
        """Which of `names` are in the graph, looking for `discovery_s` (a fresh probe needs time to see it)."""
        found = set()
        deadline = time.monotonic() + discovery_s
        while time.monotonic() < deadline and len(found) < len(names):
            found |= set(names) & set(self.node.get_node_names())
            self.spin_once()
        return sorted(found)

    def spin_once(self):
        # Nothing is subscribed: this only waits for graph events, bounded.
        self._executor.spin_once(timeout_sec=PROBE_SPIN_S)

    def wait(self, checks: dict, alive, timeout_s: float) -> list:
        """Wait until every check (name -> ReadyCheck) passes; returns the names still not ready.

        `alive()` returns the name of a process that died (or None): the wait
        stops at once then, so a crash is not reported as a time-out.
        """
        pending = dict(checks)
        deadline = time.monotonic() + timeout_s
        while pending and time.monotonic() < deadline:
            if alive() is not None:
                break
            for name, check in list(pending.items()):
                if self.is_ready(check, name):
                    del pending[name]
            if pending:
                self.spin_once()
        return list(pending)

    def close(self):
        self._executor.shutdown(timeout_sec=1.0)
        self.node.destroy_node()
        self._context.try_shutdown()
