"""Private ROS domains stay in the port-safe range, never collide with the caller's, with another process's
private domain on this host (issue 48.4) or with the tests' range; the inherit line says who can see the graph."""
import os
import random
import subprocess
import sys

import pytest

from defgg_ros.ros import domain
from defgg_ros.ros.domain import (
    PRIVATE_DOMAIN_RANGE,
    SAFE_DOMAIN_RANGE,
    TEST_DOMAIN_RANGE,
    DomainInUse,
    apply_domain_choice,
    claim_domain,
    pick_private_domain,
)

pytestmark = pytest.mark.unit


@pytest.fixture
def lock_dir(tmp_path, monkeypatch):
    """Lock files in a folder of this test, and none held by this process there yet: the ids this process holds
    in the real folder (an earlier test in the same run picked one) would otherwise read as held here too (CI,
    2026-11-29: claim_domain(1) was True, this process held 1). The locks this test takes are released after it."""
    monkeypatch.setenv(domain.LOCK_DIR_VARIABLE, str(tmp_path))
    monkeypatch.setattr(domain, "_held_locks", {})
    yield tmp_path
    for domain_id in list(domain._held_locks):
        domain.release_domain(domain_id)


def test_private_domains_are_safe_and_not_the_callers_own(monkeypatch, lock_dir):
    monkeypatch.setenv("ROS_DOMAIN_ID", "7")
    rng = random.Random(0)
    picked = []
    with pytest.raises(DomainInUse):
        while True:   # each pick holds its domain: every id of the range once, then none left
            picked.append(pick_private_domain(exclude=(8, 9), rng=rng))
    assert len(set(picked)) == len(picked)
    assert set(picked).isdisjoint({0, 7, 8, 9})      # never 0: ROS 2's default, a real cell's domain
    assert set(picked) == set(range(PRIVATE_DOMAIN_RANGE[0], PRIVATE_DOMAIN_RANGE[1] + 1)) - {7, 8, 9}
    # Fast DDS's discovery port of the highest id stays below Linux's ephemeral range (32768..).
    assert 7400 + 250 * SAFE_DOMAIN_RANGE[1] + 11 < 32768 and TEST_DOMAIN_RANGE[1] <= SAFE_DOMAIN_RANGE[1] == 101


def test_tests_and_the_cells_draw_from_disjoint_ranges():
    assert PRIVATE_DOMAIN_RANGE[1] < TEST_DOMAIN_RANGE[0]
    assert TEST_DOMAIN_RANGE[0] <= int(os.environ["ROS_DOMAIN_ID"]) <= TEST_DOMAIN_RANGE[1]   # test/conftest.py
    assert domain.domain_claimed_elsewhere(int(os.environ["ROS_DOMAIN_ID"])) is False   # this process holds it


def test_a_domain_another_process_holds_is_never_picked(lock_dir, monkeypatch):
    monkeypatch.setenv("ROS_DOMAIN_ID", "0")
    low, high = PRIVATE_DOMAIN_RANGE
    held_elsewhere = list(range(low, high))   # all but the last id of the range
    holder = subprocess.Popen(
        [sys.executable, "-c", "import sys; from defgg_ros.ros.domain import claim_domain; "
         f"ok = all(claim_domain(d) for d in {held_elsewhere}); print(ok, flush=True); sys.stdin.read()"],
        stdin=subprocess.PIPE, stdout=subprocess.PIPE, text=True, env=dict(os.environ))
    try:
        assert holder.stdout.readline().strip() == "True"
        assert not claim_domain(low) and domain.domain_claimed_elsewhere(low)
        assert pick_private_domain(rng=random.Random(1)) == high   # the only one nobody holds
        line = apply_domain_choice(str(low), {})
        assert "WARNING: another process on this host holds it" in line
    finally:
        holder.stdin.close()
        holder.wait(timeout=30)
    assert claim_domain(low)   # its locks went with it


def test_inherit_says_who_can_see_the_graph():
    localhost = {"ROS_DOMAIN_ID": "3", "ROS_AUTOMATIC_DISCOVERY_RANGE": "LOCALHOST"}
    line = apply_domain_choice("inherit", localhost)
    assert "other machines" not in line and "only this machine" in line, line
    assert "only this machine" in apply_domain_choice("inherit", {"ROS_LOCALHOST_ONLY": "1"})
    assert "discovery is off" in apply_domain_choice("inherit", {"ROS_AUTOMATIC_DISCOVERY_RANGE": "OFF"})
    for subnet in ({}, {"ROS_AUTOMATIC_DISCOVERY_RANGE": "SUBNET"}):
        assert "other machines on the network may see this graph" in apply_domain_choice("inherit", subnet)
