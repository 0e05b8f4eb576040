"""The one process launcher (defgg_ros/ros/launcher.py) and the one share-path resolver (defgg_ros/ros/share.py)."""
import io
import json
import os
import signal
import subprocess
import sys
import time

import pytest

from defgg_ros.ros import launcher
from defgg_ros.ros.launcher import NodeProcess, stop_all
from defgg_ros.ros.share import SOURCE_ROOT, share_path, share_roots

pytestmark = pytest.mark.unit

# Prints a line, then waits; with "ignore" it also ignores SIGINT (a node that hangs on shutdown).
CHILD = """
import signal, sys, time
if sys.argv[1] == "ignore":
    signal.signal(signal.SIGINT, signal.SIG_IGN)
print("ready", flush=True)
time.sleep(60)
"""


def _wait_for(predicate, timeout_s=10.0):
    deadline = time.monotonic() + timeout_s
    while not predicate():
        assert time.monotonic() < deadline, "timed out"
        time.sleep(0.02)


def test_output_is_forwarded_with_the_name_and_sigint_stops_a_well_behaved_child():
    out = io.StringIO()
    process = NodeProcess("child", [sys.executable, "-c", CHILD, "obey"], out=out)
    _wait_for(lambda: "ready" in process.tail)
    assert process.returncode() is None
    assert process.stop() != 0 and "[child] ready" in out.getvalue()


def test_a_child_ignoring_sigint_gets_sigterm_after_the_grace(monkeypatch, tmp_path):
    monkeypatch.setattr(launcher, "SIGINT_GRACE_S", 0.5)
    log = tmp_path / "child.log"
    process = NodeProcess("stubborn", [sys.executable, "-c", CHILD, "ignore"], log_path=log)
    _wait_for(lambda: "ready" in process.tail)
    started = time.monotonic()
    codes = stop_all([process])
    assert codes == {"stubborn": -15}  # SIGTERM, after the SIGINT grace
    assert time.monotonic() - started >= 0.5        # SIGTERM only after the SIGINT grace
    assert log.read_text().strip() == "ready"


def test_child_env_sets_the_transport_and_an_optional_private_domain():
    env = launcher.child_env(17, base={"PATH": "/bin"})
    assert env["ROS_DOMAIN_ID"] == "17" and env["ROS_AUTOMATIC_DISCOVERY_RANGE"] == "LOCALHOST"
    assert env["FASTRTPS_DEFAULT_PROFILES_FILE"].endswith("defgg_ros/ros/fastdds_profile.xml")
    assert env["PYTHONUNBUFFERED"] == "1"
    assert launcher.child_env(None, base={"FASTRTPS_DEFAULT_PROFILES_FILE": "mine.xml"})[
        "FASTRTPS_DEFAULT_PROFILES_FILE"] == "mine.xml"


def test_share_paths_resolve_in_the_source_tree_first():
    assert share_roots()[0] == SOURCE_ROOT
    config = share_path("sim_bringup", "config", "sim_cell.yaml")
    assert config == SOURCE_ROOT / "sim_bringup" / "config" / "sim_cell.yaml"
    assert share_path("models", "defgg_cnn.pt").is_file()
    # A missing file names the source tree's place for it.
    assert share_path("models", "no_such.pt") == SOURCE_ROOT / "models" / "no_such.pt"


# A real rclpy node through the nodes' one main body, and a parent that starts a child with NodeProcess.
IDLE_NODE = ("from rclpy.node import Node\nfrom defgg_ros.nodes.node_main import run_node\n"
             "run_node('idle_node', lambda: (print('ready', flush=True), Node('idle_node'))[1])\n")
RECORDER = "import sys; from defgg_ros.sessions.record import main; sys.exit(main())"
SUPERVISOR = """
import json, sys, time
from defgg_ros.ros.launcher import NodeProcess
child = NodeProcess("child", json.loads(sys.argv[1]), log_path=sys.argv[2])
print(child.pid, flush=True)
time.sleep(120)
"""


def _running(pid: int) -> bool:
    """Alive and not a zombie (a container's pid 1 may never reap an orphan)."""
    try:
        with open(f"/proc/{pid}/stat") as stat:
            return stat.read().rsplit(")", 1)[1].split()[0] != "Z"
    except FileNotFoundError:
        return False


@pytest.mark.parametrize("child", ["node", "recorder"])
def test_a_child_stops_itself_when_the_process_that_started_it_is_killed(child, tmp_path):
    """A node stops; the session recorder (`defgg-bringup --record`) ends its bag instead of recording on."""
    log, bag = tmp_path / "child.log", tmp_path / "session"
    argv, started = {"node": ([sys.executable, "-c", IDLE_NODE], "ready"),
                     "recorder": ([sys.executable, "-c", RECORDER, str(bag)], "recording into")}[child]
    parent = subprocess.Popen([sys.executable, "-c", SUPERVISOR, json.dumps(argv), str(log)],
                              stdout=subprocess.PIPE, text=True)
    child_pid = int(parent.stdout.readline())
    try:
        _wait_for(lambda: log.exists() and started in log.read_text(), timeout_s=30.0)
        parent.kill()                # SIGKILL: no chance to stop its child
        parent.wait()
        _wait_for(lambda: not _running(child_pid), timeout_s=20.0)
        assert f"the process that started it (pid {parent.pid}) is gone: shutting down" in log.read_text()
        if child == "recorder":
            assert f"wrote {bag}" in log.read_text() and (bag / "metadata.yaml").is_file()
    finally:
        if _running(child_pid):
            os.kill(child_pid, signal.SIGKILL)


def test_the_watch_is_only_for_children_of_a_node_process(monkeypatch):
    monkeypatch.delenv(launcher.SUPERVISOR_PID_VARIABLE, raising=False)
    assert launcher.watch_supervisor("n") is None               # started by hand, ros2 run or a launch file
    monkeypatch.setenv(launcher.SUPERVISOR_PID_VARIABLE, str(os.getpid()))
    assert launcher.watch_supervisor("n") is None               # inherited from a live grandparent


# A process whose recorded starter already died (a zombie nobody reaped) before its watch began: it must stop.
LATE_WATCH = """
import os, subprocess, sys, time
from defgg_ros.ros.launcher import SUPERVISOR_PID_VARIABLE, watch_supervisor
dead = subprocess.Popen([sys.executable, "-c", "pass"])
time.sleep(1.0)                     # exited, not waited for: a zombie
os.environ[SUPERVISOR_PID_VARIABLE] = str(dead.pid)
watch_supervisor("late")
assert SUPERVISOR_PID_VARIABLE not in os.environ   # not handed on to what this process starts
time.sleep(30)
"""


def test_a_watch_that_starts_after_its_starter_died_stops_the_process_at_once():
    started = time.monotonic()
    proc = subprocess.run([sys.executable, "-c", LATE_WATCH], capture_output=True, text=True, timeout=60)
    assert proc.returncode == -signal.SIGTERM, proc.stderr
    assert "late: the process that started it" in proc.stderr and time.monotonic() - started < 20
