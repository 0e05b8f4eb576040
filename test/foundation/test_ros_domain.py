"""Private ROS domains stay in the port-safe range and never collide with the caller's."""
import random

from defgg_ros.ros.domain import SAFE_DOMAIN_RANGE, pick_private_domain


def test_private_domains_are_safe_and_not_the_callers_own(monkeypatch):
    monkeypatch.setenv("ROS_DOMAIN_ID", "7")
    rng = random.Random(0)
    picked = {pick_private_domain(exclude=(8, 9), rng=rng) for _ in range(2000)}
    assert picked.isdisjoint({0, 7, 8, 9})      # never 0: ROS 2's default, a real cell's domain
    assert min(picked) >= SAFE_DOMAIN_RANGE[0] and max(picked) <= SAFE_DOMAIN_RANGE[1] == 101
    # Fast DDS's discovery port of the highest id stays below Linux's ephemeral range (32768..).
    assert 7400 + 250 * max(picked) + 11 < 32768
    assert len(picked) == SAFE_DOMAIN_RANGE[1] - SAFE_DOMAIN_RANGE[0] + 1 - 4
