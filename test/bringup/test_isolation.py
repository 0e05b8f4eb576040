"""Isolation by default (issue 27.6): the simulated cell's graph stays off domain 0 and off the network.

A cell started by `defgg-bringup` the way a user starts it (no ROS_DOMAIN_ID in the shell) must be
invisible to a process listening in domain 0 with default discovery, while a listener that joins the
domain named in the cell's first log line sees it (so the listener can see a graph at all). The real
cell inherits the shell's domain and warns when it finds a simulated driver there.
"""
import json
import os
import random
import re
import subprocess
import sys
import time

import pytest

from defgg_ros.bringup.node_set import load_node_set
from defgg_ros.ros.domain import LOCALHOST_RANGE, apply_domain_choice, parse_domain_choice

pytestmark = pytest.mark.ros

SIM_CELL = load_node_set("sim_cell")
CONFIG = SIM_CELL.config_dir
SCENE = CONFIG.parent / "scenes" / "rigid_box.yaml"


def _set_yaml(name: str, node_names, header: str) -> str:
    """A node set of some of sim_cell's nodes (same modules, parameter files and ready checks)."""
    lines = [f"name: {name}", header, "nodes:"]
    for entry in SIM_CELL.nodes:
        if entry.name in node_names:
            lines += [f"  - name: {entry.name}", f"    module: {entry.module}",
                      f"    params: [{', '.join(entry.params_files)}]",
                      f"    ready: {{{entry.ready.kind}: {entry.ready.name}}}"]
    return "\n".join(lines) + "\n"


# A demo-like graph: the simulated driver (it publishes joint states, camera frames, /clock) and the
# executor (it publishes the arm's joint trajectories), as sim_cell starts them.
DEMO_LIKE_SET = _set_yaml("demo_like", ("fake_panda_driver", "executor_node"),
                          "use_sim_time: true\nros_domain: private")
LISTEN_S = 4.0
# Lists every node and topic it discovers in its domain for a while, as JSON.
LISTENER = f"""
import json, time, rclpy
from rclpy.node import Node
rclpy.init()
node = Node("domain_listener")
nodes, topics = set(), set()
deadline = time.monotonic() + {LISTEN_S}
while time.monotonic() < deadline:
    rclpy.spin_once(node, timeout_sec=0.1)
    nodes |= set(node.get_node_names())
    topics |= {{name for name, _ in node.get_topic_names_and_types()}}
print(json.dumps({{"nodes": sorted(nodes), "topics": sorted(topics)}}))
"""


def _user_shell_env(**extra) -> dict:
    """A shell with no ROS settings (what `make demo` gets on a fresh machine), plus `extra`."""
    env = {k: v for k, v in os.environ.items() if k not in ("ROS_DOMAIN_ID", "ROS_AUTOMATIC_DISCOVERY_RANGE")}
    env.update(extra)
    return env


def _listen(env) -> dict:
    proc = subprocess.run([sys.executable, "-c", LISTENER], env=env, capture_output=True, text=True, timeout=60)
    assert proc.returncode == 0, proc.stderr
    return json.loads(proc.stdout.strip().splitlines()[-1])


def _start_bringup(set_path, env, *args):
    return subprocess.Popen([sys.executable, "-m", "defgg_ros.bringup.cli", "--set", str(set_path), *args],
                            env=env, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)


def _read_until(proc, pattern, timeout_s=120.0) -> list:
    """Lines of proc's stdout up to the first that matches `pattern` (fails on exit or time-out)."""
    lines, deadline = [], time.monotonic() + timeout_s
    while time.monotonic() < deadline:
        line = proc.stdout.readline()
        if not line:
            pytest.fail(f"bringup exited before '{pattern}': {''.join(lines)}{proc.stderr.read()}")
        lines.append(line)
        if re.search(pattern, line):
            return lines
    pytest.fail(f"no '{pattern}' within {timeout_s} s: {''.join(lines)}")


def _stop(proc) -> str:
    """SIGINT (the bringup stops its nodes), then its remaining stderr."""
    proc.send_signal(2)
    try:
        return proc.communicate(timeout=30)[1]
    except subprocess.TimeoutExpired:
        proc.kill()
        return proc.communicate()[1]


def test_a_listener_in_domain_0_sees_nothing_of_a_demo_like_graph(tmp_path):
    set_path = tmp_path / "demo_like.yaml"
    set_path.write_text(DEMO_LIKE_SET)
    proc = _start_bringup(set_path, _user_shell_env(), "--scene", str(SCENE))
    try:
        lines = _read_until(proc, "cell ready")
        first = lines[0]
        # The first log line says where the graph is and that discovery stays on this host.
        match = re.match(r"defgg-bringup: ROS domain (\d+) \(private.*discovery localhost only", first)
        assert match, first
        domain = int(match.group(1))
        assert domain != 0
        in_domain_0 = _listen(_user_shell_env(ROS_DOMAIN_ID="0"))
        joined = _listen(_user_shell_env(ROS_DOMAIN_ID=str(domain), ROS_AUTOMATIC_DISCOVERY_RANGE=LOCALHOST_RANGE))
    finally:
        _stop(proc)
    ours = {"fake_panda_driver", "executor_node"}
    assert ours <= set(joined["nodes"]), joined  # the listener does see a graph it shares a domain with
    assert {"/clock", "/joint_states"} <= set(joined["topics"]), joined
    assert not ours & set(in_domain_0["nodes"]), in_domain_0
    assert "/clock" not in in_domain_0["topics"], in_domain_0  # only a simulator publishes /clock


def test_the_real_cell_set_warns_about_a_simulated_driver_on_its_domain(tmp_path, rclpy_context):
    from rclpy.node import Node

    # The real cell's set minus the heavy nodes: what matters is its domain rule and its warning list.
    real = (CONFIG / "real_cell.yaml").read_text()
    assert "ros_domain: inherit" in real and "warn_if_present: [fake_panda_driver]" in real
    set_path = tmp_path / "real_like.yaml"
    set_path.write_text(_set_yaml("real_like", ("executor_node",),
                                  "ros_domain: inherit\nwarn_if_present: [fake_panda_driver]"))
    # A node named like the simulated driver, in this test's (private) domain, which the set inherits.
    intruder = Node("fake_panda_driver", context=rclpy_context)
    env = dict(os.environ)  # conftest's private domain, localhost-only
    proc = _start_bringup(set_path, env)
    stderr = ""
    try:
        lines = _read_until(proc, "cell ready")
        assert re.match(rf"defgg-bringup: ROS domain {os.environ['ROS_DOMAIN_ID']}, .*inherited", lines[0]), lines[0]
        _read_until(proc, "looked for", timeout_s=30.0)  # the check ran
    finally:
        stderr = _stop(proc)
        intruder.destroy_node()
    assert "WARNING: node 'fake_panda_driver'" in stderr, stderr


@pytest.mark.unit
def test_domain_choices():
    env = {"ROS_DOMAIN_ID": "7"}
    line = apply_domain_choice("private", env, random.Random(0))
    assert env["ROS_DOMAIN_ID"] not in ("0", "7") and env["ROS_AUTOMATIC_DISCOVERY_RANGE"] == "LOCALHOST"
    assert f"ROS domain {env['ROS_DOMAIN_ID']} (private" in line
    env = {"ROS_DOMAIN_ID": "0", "ROS_AUTOMATIC_DISCOVERY_RANGE": "SUBNET"}
    assert "inherited" in apply_domain_choice("inherit", env) and env["ROS_DOMAIN_ID"] == "0"
    assert env["ROS_AUTOMATIC_DISCOVERY_RANGE"] == "SUBNET"
    apply_domain_choice(parse_domain_choice("42"), env)
    assert env == {"ROS_DOMAIN_ID": "42", "ROS_AUTOMATIC_DISCOVERY_RANGE": "LOCALHOST"}
    for bad in ("public", "102", "-1"):
        with pytest.raises(ValueError):
            parse_domain_choice(bad)
    assert load_node_set("sim_cell").ros_domain == "private"
    assert load_node_set("real_cell").ros_domain == "inherit"
