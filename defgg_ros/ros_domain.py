"""Private ROS domain ids for graphs that must not see the caller's (replays, tests, benchmarks).

Ids 0..101 only: Fast DDS maps domain d to UDP ports 7400 + 250 * d (+ offsets), and above 101
those land in Linux's ephemeral port range (32768..60999), where any other socket may already hold
them; CI lost whole replayed frames in domains 101-230. ROS 2's own docs give the same safe range.
"""
import os
import random

SAFE_DOMAIN_RANGE = (0, 101)


def pick_private_domain(exclude=(), rng=random) -> int:
    """A random safe domain id other than this process's ROS_DOMAIN_ID and the ids in `exclude`."""
    taken = {str(d) for d in exclude} | {os.environ.get("ROS_DOMAIN_ID", "0")}
    choices = [d for d in range(SAFE_DOMAIN_RANGE[0], SAFE_DOMAIN_RANGE[1] + 1) if str(d) not in taken]
    return rng.choice(choices)
