"""The one process launcher (defgg_ros/ros/launcher.py) and the one share-path resolver (defgg_ros/ros/share.py)."""
import io
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
