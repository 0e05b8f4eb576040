"""How much squeeze the defgraspsim protocol's finger lock keeps, and why the rigid stand-in is force-held.

For box_small and a pilot EGAD shape at each modulus: grasp and pick up under the defgraspsim protocol, then
hold still (zero gravity) for HOLD_S and print each finger's motor force as a share of the set force F/2 at
the start and end of the hold, for three ways of holding the fingers after pickup:
  ours        gear released, each finger on a stiff position drive (hand.lock_fingers; applied here to
              the rigid stand-in too, to show why the protocol does not lock it)
  gear_weak   gear kept, fingers on the weak position drive of the open hand (50 N, default gain)
  force       fingers stay on the force-limited close (F/2), as the rigid stand-in
PyBullet's soft contact forces are unreliable, so the squeeze is read from the finger motors.

  .venv/bin/python bench/bench_finger_lock.py
"""
from __future__ import annotations

import argparse
import math
import sys

import pybullet as p

from defgg_ros.sim import objects, world
from defgg_ros.sim.trial import TrialSettings, WorldGrasp, _Trial

HOLD_S = 0.5
CASES = (("box_small", WorldGrasp((0.0, 0.0, 0.02), math.pi / 2, 0.03)),)
MODES = ("ours", "gear_weak", "force")


class _HeldTrial(_Trial):
    """A trial whose fingers are held after pickup by `mode` instead of the protocol's rule."""

    def __init__(self, *args, mode: str):
        super().__init__(*args)
        self.mode = mode

    def hold_fingers_for_tests(self):
        if self.mode == "ours":
            self.hand.lock_fingers()
            self.fingers_locked = True
        elif self.mode == "gear_weak":
            _weak_lock(self.hand)
        self.step(self.check_steps)


def squeeze_shares(name, grasp, e, mode, client):
    settings = TrialSettings().with_fields(protocol="defgraspsim")
    run = _HeldTrial(client, objects.ObjectSpec(objects.get_shape(name), e), grasp, settings, (0, 0), 0.0,
                     mode=mode)
    run.grasp_and_lift()
    start = run.hand.finger_forces_n()
    run.step(run.seconds(HOLD_S))
    end = run.hand.finger_forces_n()
    half = run.force_n
    return [f / half for f in start], [f / half for f in end], half


def _weak_lock(hand):
    for j in hand.FINGER_LINKS:
        q = p.getJointState(hand.body_id, j, physicsClientId=hand.client)[0]
        p.setJointMotorControl2(hand.body_id, j, p.POSITION_CONTROL, targetPosition=q, force=50.0,
                                physicsClientId=hand.client)


def main() -> int:
    argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter).parse_args()
    client = world.connect()
    print(f"| object | E (Pa) | hold | F/2 (N) | squeeze after pickup (share of F/2) | after {HOLD_S} s |")
    print("|---|---|---|---|---|---|")
    for name, grasp in CASES:
        for e in (2e4, 2e5, 2e6, 2e9):
            for mode in MODES:
                start, end, half = squeeze_shares(name, grasp, e, mode, client)
                print(f"| {name} | {e:.0e} | {mode} | {half:.3f} | {start[0]:.2f} / {start[1]:.2f} | "
                      f"{end[0]:.2f} / {end[1]:.2f} |", flush=True)
    p.disconnect(client)
    return 0


if __name__ == "__main__":
    sys.exit(main())
