"""defgg_ros/nodes/node_main.run_node: a stop requested while the node is being built is a clean exit.

A SIGINT after rclpy.init shuts the context down; if its KeyboardInterrupt is lost on the way (a library's
`except BaseException`), the constructor's next rclpy call fails ("context is not valid") and the launcher's
stop saw exit 1 and a traceback (the fake driver did, SIGINT 0.5 s after its start). Real processes, real
signals, real rclpy; the node is built after the signal has been handled, so the race is certain.
"""
import os
import subprocess
import sys

import pytest

pytestmark = pytest.mark.ros

CHILD = """
import os, signal, sys, time
import rclpy
from rclpy.node import Node
from defgg_ros.nodes.node_main import run_node

def make_node():
    if sys.argv[1] == "stop":
        try:
            os.kill(os.getpid(), signal.SIGINT)  # the launcher's stop, while the node is being built
            deadline = time.monotonic() + 5.0
            while rclpy.ok() and time.monotonic() < deadline:
                time.sleep(0.01)                  # rclpy's handler shuts the context down
        except KeyboardInterrupt:
            pass                                  # lost in a library's `except BaseException` (trimesh has them)
    node = Node("built_late")
    raise ValueError("a bad parameter")          # if the node could be built: a start-up error

run_node("probe_node", make_node)
"""


def _run(mode):
    env = dict(os.environ, ROS_AUTOMATIC_DISCOVERY_RANGE="LOCALHOST")
    return subprocess.run([sys.executable, "-c", CHILD, mode], capture_output=True, text=True, timeout=60, env=env)


def test_a_stop_while_the_node_is_built_exits_0_without_a_traceback():
    done = _run("stop")
    assert done.returncode == 0, done.stderr
    assert "Traceback" not in done.stderr


def test_a_start_up_error_without_a_stop_is_still_exit_2_with_one_line():
    done = _run("run")
    assert done.returncode == 2, done.stderr
    assert done.stderr.strip() == "probe_node: a bad parameter"


# A node that stops hardware before it exits (the executor: issue 48.1). Its timer sends the signal (or raises) once
# the node spins; stop_for_exit must run while callbacks still run, before anything is destroyed.
STOPPING_CHILD = """
import os, signal, sys, time
from rclpy.node import Node
from defgg_ros.nodes.node_main import run_node

mode, threads = sys.argv[1], int(sys.argv[2])

class Probe(Node):
    def __init__(self):
        super().__init__("stopping_probe")
        self.ticks = 0
        self.create_timer(0.01, self.tick)

    def tick(self):
        self.ticks += 1
        if self.ticks == 20:
            if mode == "raise":
                raise RuntimeError("a bug in a callback")
            os.kill(os.getpid(), signal.SIGINT if mode == "sigint" else signal.SIGTERM)

    def stop_for_exit(self, spin_once):
        before, deadline = self.ticks, time.monotonic() + 5.0
        while self.ticks < before + 5 and time.monotonic() < deadline:
            spin_once(0.05)
        print(f"stopped while callbacks ran: {self.ticks - before >= 5}", flush=True)
        return "could not confirm that the arm stopped" if mode == "unconfirmed" else ""

    def destroy_node(self):
        print("destroyed", flush=True)
        super().destroy_node()

run_node("stopping_probe", Probe, stops_hardware=True, threads=threads)
"""


@pytest.mark.parametrize("threads", [1, 4], ids=["single_threaded", "threaded"])
@pytest.mark.parametrize("mode, code", [("sigterm", 0), ("sigint", 0), ("unconfirmed", 1), ("raise", 1)])
def test_a_node_that_stops_hardware_stops_it_before_it_is_torn_down(mode, code, threads):
    """threaded: the executor node's ThreadedExecutor (4 threads). It lost a callback's exception (it asked the
    thread pool's future, not the rclpy Task that keeps the exception): the node spun on, no stop, no exit 1."""
    env = dict(os.environ, ROS_AUTOMATIC_DISCOVERY_RANGE="LOCALHOST")
    done = subprocess.run([sys.executable, "-c", STOPPING_CHILD, mode, str(threads)], capture_output=True, text=True,
                          timeout=60, env=env)
    assert done.returncode == code, (done.stdout, done.stderr)
    assert done.stdout.split() == ["stopped", "while", "callbacks", "ran:", "True", "destroyed"], done.stdout
    if mode == "unconfirmed":
        assert "stopping_probe: could not confirm that the arm stopped" in done.stderr
    if mode == "raise":
        assert "RuntimeError: a bug in a callback" in done.stderr
