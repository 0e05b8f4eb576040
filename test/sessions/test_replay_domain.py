"""The replay picks a ROS domain nobody else is in (real DDS discovery, real nodes)."""
import pytest
import rclpy
from rclpy.node import Node

from defgg_ros.sessions import replay


def test_a_domain_with_a_live_node_is_skipped(rclpy_context, monkeypatch):
    own_domain = rclpy_context.get_domain_id()
    node = Node("replay_domain_squatter", context=rclpy_context)
    try:
        assert "replay_domain_squatter" in replay.nodes_in_domain(own_domain)
        free = next(d for d in range(101, -1, -1) if d != own_domain)
        offered = iter([own_domain, free])
        monkeypatch.setattr(replay, "pick_private_domain", lambda exclude=(): next(offered))
        said = []
        assert replay.pick_empty_domain(log=said.append) == free
        assert said and f"ROS domain {own_domain} is in use" in said[0] and "replay_domain_squatter" in said[0]
    finally:
        node.destroy_node()


def test_no_free_domain_is_a_clear_error(rclpy_context, monkeypatch):
    node = Node("replay_domain_squatter", context=rclpy_context)
    try:
        monkeypatch.setattr(replay, "pick_private_domain", lambda exclude=(): rclpy_context.get_domain_id())
        with pytest.raises(replay.GraphError, match=r"no free ROS domain .*--domain-id"):
            replay.pick_empty_domain(log=lambda _: None, attempts=2)
    finally:
        node.destroy_node()
    assert rclpy.ok(context=rclpy_context)
