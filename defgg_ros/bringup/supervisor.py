"""Start a node set, wait until every node is ready, watch them, stop them all.

Used by `defgg-bringup` (cli.py), by the demo and by tests. One node dying
stops the others; `failed_node` says which died and how.
"""
import sys
import time
from dataclasses import dataclass

from defgg_ros.bringup.node_set import NodeSet, node_command
from defgg_ros.bringup.readiness import ReadinessProbe
from defgg_ros.ros.launcher import NodeProcess, stop_all
from defgg_ros.ros.transport import use_large_message_transport

DEFAULT_READY_TIMEOUT_S = 120.0


class BringupError(RuntimeError):
    """A node did not start, did not become ready, or died."""


@dataclass(frozen=True)
class NodeExit:
    name: str
    returncode: int

    def describe(self) -> str:
        how = f"exit code {self.returncode}" if self.returncode >= 0 else f"signal {-self.returncode}"
        return f"node {self.name} died ({how})"


class Bringup:
    """The processes of one node set. Use as a context manager so they always stop."""

    def __init__(self, node_set: NodeSet, overrides: dict | None = None, extra: dict | None = None, out=None):
        """overrides: node name -> {parameter: value}; extra: name -> argv of extra processes (recorder)."""
        self.node_set = node_set
        self._overrides = overrides or {}
        self._extra = extra or {}
        self._out = out or sys.stdout
        self.processes: dict = {}

    def __enter__(self):
        self.start()
        return self

    def __exit__(self, *exc):
        self.stop()
        return False

    def start(self) -> None:
        # Large shared-memory segments: with the default transports camera-sized messages between
        # processes were mostly lost (defgg_ros/ros/fastdds_profile.xml).
        use_large_message_transport()
        unknown = set(self._overrides) - {n.name for n in self.node_set.nodes}
        if unknown:
            raise BringupError(f"parameter overrides for nodes not in set {self.node_set.name}: {sorted(unknown)}")
        for entry in self.node_set.nodes:
            argv = node_command(entry, self.node_set.use_sim_time, self._overrides.get(entry.name))
            self.processes[entry.name] = NodeProcess(entry.name, argv, out=self._out)
        for name, argv in self._extra.items():
            self.processes[name] = NodeProcess(name, argv, out=self._out)

    def failed_node(self) -> NodeExit | None:
        """The first process that has exited, if any."""
        for name, proc in self.processes.items():
            code = proc.returncode()
            if code is not None:
                return NodeExit(name, code)
        return None

    def wait_ready(self, timeout_s: float = DEFAULT_READY_TIMEOUT_S, stop_requested=None) -> float:
        """Block until every node's ready check passes; BringupError names the culprit. Returns seconds taken.

        stop_requested: an optional threading.Event that ends the wait early (Ctrl-C while starting).
        """
        t0 = time.monotonic()
        probe = ReadinessProbe()
        try:
            checks = {n.name: n.ready for n in self.node_set.nodes}
            stopping = stop_requested.is_set if stop_requested is not None else (lambda: False)
            pending = probe.wait(checks, lambda: self.failed_node() or (stopping() or None), timeout_s)
        finally:
            probe.close()
        dead = self.failed_node()
        if dead is not None:
            raise BringupError(f"{dead.describe()} before the cell was ready; its last lines:\n"
                               + "\n".join(self.processes[dead.name].tail))
        if stop_requested is not None and stop_requested.is_set():
            raise BringupError("stop requested before the cell was ready")
        if pending:
            details = ", ".join(f"{n} ({checks[n].kind} {checks[n].name})" for n in pending)
            raise BringupError(f"not ready after {timeout_s:.0f} s: {details}")
        return time.monotonic() - t0

    def nodes_present(self, names) -> list:
        """Which of `names` are nodes in this process's ROS domain right now (after a short discovery wait)."""
        if not names:
            return []

        probe = ReadinessProbe()
        try:
            return probe.nodes_present(names)
        finally:
            probe.close()

    def stop(self) -> dict:
        """Stop every process (reverse start order, the launcher's shutdown rule); returns name -> exit code."""
        return stop_all(reversed(list(self.processes.values())))
