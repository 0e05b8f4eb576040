"""The replay picks a ROS domain nobody else is in (real DDS discovery, real nodes)."""
import pytest
import rclpy
from rclpy.context import Context
from rclpy.node import Node

from defgg_ros.ros.domain import pick_private_domain
from defgg_ros.sessions import replay

# Discovery of the squatter, in this process, took more than 3 s at a load of 8 (the full suite, 2026-12-02):
# these tests check what the replay does with an occupied domain, not how fast discovery is.
LISTEN_S = 10.0


@pytest.fixture
def squatter():
    """(domain id, node): a node alone in a private domain of its own (this process's domain holds
    nodes left by earlier tests)."""
    context = Context()
    domain_id = pick_private_domain()
    rclpy.init(context=context, domain_id=domain_id)
    node = Node("replay_domain_squatter", context=context)
    yield domain_id, node
    node.destroy_node()
    context.try_shutdown()


def test_a_domain_with_a_live_node_is_skipped(squatter, monkeypatch):
    taken, _ = squatter
    assert replay.nodes_in_domain(taken, LISTEN_S)   # occupied (the probe stops at the first node it sees)
    free = pick_private_domain(exclude=(taken,))
    offered = iter([taken, free])
    monkeypatch.setattr(replay, "pick_private_domain", lambda exclude=(): next(offered))
    said = []
    assert replay.pick_empty_domain(log=said.append, listen_s=LISTEN_S) == free
    assert said and f"ROS domain {taken} is in use" in said[0]


def test_no_free_domain_is_a_clear_error(squatter, monkeypatch):
    taken, _ = squatter
    monkeypatch.setattr(replay, "pick_private_domain", lambda exclude=(): taken)
    with pytest.raises(replay.GraphError, match=r"no free ROS domain .*--domain-id"):
        replay.pick_empty_domain(log=lambda _: None, attempts=2, listen_s=LISTEN_S)
