"""The trial hand's pressing close (finger_drive "press", sim/finger_press.py): on an FEM body each finger pushes
with the force it is given, as the cell's hand does; the speed drive (fem_v1-v5's labels) stops at ~ its
momentum per step (hand.speed_drive_ceiling_n) whatever force it is given."""
import math

import pytest

from defgg_ros.sim import hand as hand_mod
from defgg_ros.sim import objects, world
from defgg_ros.sim.hand import speed_drive_ceiling_n, world_T_hand

pytestmark = pytest.mark.unit

MODULUS_PA = 2e4
CLOSE_SPEED_MPS = 0.1       # the trials' (TrialMotion.close_speed_mps)


def squeezed_opening_mm(client, force_n: float, press: bool) -> float:
    """The box_small (3 cm across here) squeezed at its centre; the opening after 0.3 s."""
    trial_world = world.create_world(client, [MODULUS_PA])
    objects.load_object(client, objects.ObjectSpec(objects.get_shape("box_small"), MODULUS_PA), (0.0, 0.0), 0.0)
    trial_world.step(round(0.05 / trial_world.time_step_s))
    hand = hand_mod.create_hand(client, world_T_hand((0.0, 0.0, 0.02), math.pi / 2), 0.04)
    hand.close(force_n, CLOSE_SPEED_MPS, press=press)
    trial_world.before_step = hand.drive
    trial_world.step(round(0.3 / trial_world.time_step_s))
    return hand.finger_opening_m() * 1000


def test_the_pressing_hand_squeezes_harder_with_more_force_and_the_speed_drive_does_not(client):
    ceiling_n = speed_drive_ceiling_n(world.time_step_for([MODULUS_PA]), CLOSE_SPEED_MPS)
    assert ceiling_n == pytest.approx(1.0)
    pressed = [squeezed_opening_mm(client, f, True) for f in (0.5, 3.0)]
    driven = [squeezed_opening_mm(client, f, False) for f in (0.5, 3.0)]
    # Below the ceiling both drives press with the force; above it only the pressing one does (measured 2026-11-30:
    # 33.65 -> 31.44 mm pressing, 33.65 -> 33.21 mm speed-driven, as at 1 N).
    assert pressed[0] == pytest.approx(driven[0], abs=0.05), (pressed, driven)
    assert pressed[0] - pressed[1] > 1.0, pressed
    assert driven[0] - driven[1] < 0.3 * (pressed[0] - pressed[1]), (pressed, driven)


def test_a_pressing_hand_reports_the_force_it_pushes_with(client):
    trial_world = world.create_world(client, [MODULUS_PA])
    objects.load_object(client, objects.ObjectSpec(objects.get_shape("box_small"), MODULUS_PA), (0.0, 0.0), 0.0)
    hand = hand_mod.create_hand(client, world_T_hand((0.0, 0.0, 0.02), math.pi / 2), 0.04)
    hand.close(2.0, CLOSE_SPEED_MPS, press=True)
    trial_world.before_step = hand.drive
    trial_world.step(round(0.3 / trial_world.time_step_s))
    assert hand.pressing.pressing and hand.finger_forces_n() == [2.0, 2.0]
    hand.lock_fingers()                               # the lock ends the pressing close
    assert hand.pressing is None
    trial_world.step(10)
