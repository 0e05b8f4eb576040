"""How hard and how far to close the Franka Hand, chosen from Young's modulus (or the grasp's own force).

Why a rule at all: the same grasp force cannot serve a foam cube and a
wooden block -- a force that holds a rigid object by friction squashes a
2e4 Pa foam, and one gentle enough for the foam lets a stiff object slip.
DefGraspSim (Huang et al.) grew the grasp force with the logarithm of the
modulus; so did our dataset generator, and the executor uses *that same
function* (`defgg_ros.sim.trial.grasp_force_n`, the force of the training
labels), because Def-GG-CNN's quality is the probability that a grasp holds
when closed with that force: executing with another force would execute a
different grasp than the one the network rated. The force is clipped to the
hand's continuous rating. A grasp planned by a model whose labels used another
rule (defgraspsim: FOS * m * g / mu, from the object's mass) carries that force
(Grasp.finger_force_n, computed by the inference node: planning/grip_estimate.py)
and is closed with it instead. Soft objects are also closed more slowly, so the
fingers stop on the object instead of driving through its first millimetres.

The closing width follows franka_gripper's grasp semantics: the command
succeeds when the fingers stop inside [width - eps_inner, width + eps_outer].
We accept anything between "not empty" (`MISSED_WIDTH_M`) and the opening
we started from: a soft object legitimately ends up much narrower than the
predicted width, and the sequence judges the outcome itself.
"""
import math
from dataclasses import dataclass

from defgg_ros.constants import (
    GRIPPER_MAX_FORCE_N,
    GRIPPER_MAX_WIDTH_M,
    MAX_SOFT_BODY_YOUNGS_MODULUS_PA,
    YOUNGS_MODULUS_MAX_PA,
    YOUNGS_MODULUS_MIN_PA,
)

# The legacy labels' force (defgg_ros/grip_force.py), the one the executor grasps with.
from defgg_ros.grip_force import grasp_force_n as label_grasp_force_n

# Closing speeds (opening rate, franka_gripper allows up to 0.1 m/s).
SOFT_CLOSING_SPEED_MPS = 0.02
RIGID_CLOSING_SPEED_MPS = 0.05
OPENING_SPEED_MPS = 0.08
# The hand opens this much wider than the planned grasp before the descent (5 mm a side): the training
# trials' start (sim.trial.OPENING_CLEARANCE_M). See `pre_grasp_opening_m`.
PRE_GRASP_EXTRA_OPENING_M = 0.01
# Fingers closed to less than this = nothing between them (missed/dropped).
MISSED_WIDTH_M = 0.004
# A grasp that ends this close to the opening it started from never closed: a finger rests on the object (the
# grasp centre is off the object). Without this the gripper reported success and the pick failed later as a
# "slip", and a squeeze read the resting finger as a rigid object.
NOT_CLOSED_TOLERANCE_M = 0.003


class GripperRuleError(ValueError):
    """A modulus or width the rule cannot work with."""


@dataclass(frozen=True)
class GraspCommand:
    """A franka_gripper-style grasp plus the opening to take before it."""

    pre_open_width_m: float
    width_m: float
    epsilon_inner_m: float
    epsilon_outer_m: float
    speed_mps: float
    force_n: float


def grasp_force_n(youngs_modulus_pa: float) -> float:
    """The training labels' grasp force (grows with log10 E), within the hand's rating."""
    e = float(youngs_modulus_pa)
    if not math.isfinite(e) or not YOUNGS_MODULUS_MIN_PA <= e <= YOUNGS_MODULUS_MAX_PA:
        raise GripperRuleError(f"Young's modulus {e} Pa is outside [{YOUNGS_MODULUS_MIN_PA:g}, "
                               f"{YOUNGS_MODULUS_MAX_PA:g}] Pa")
    return min(float(label_grasp_force_n(e)), GRIPPER_MAX_FORCE_N)


def pre_grasp_opening_m(grasp_width_m: float) -> float:
    """How far to open before the descent: the planned grasp's opening + PRE_GRASP_EXTRA_OPENING_M, at most
    the hand's full opening.

    The planned opening is geometric (planning/tabletop_grasps: the object's extent seen along the closing
    line + 6 mm clearance a side), so the fingers come down 11 mm clear of what the camera saw, as in the
    training trials. Opening fully instead (80 mm, the rule while the width was the network's, which ran
    14-40 mm narrower than the object) swept up to 4 cm from the grasp's centre: a ring's far tube, a
    neighbour in a dense bin or the bin's wall took the finger (docs/perception.md, "Pre-grasp opening").
    The planner checks the pads over the same sweep (it calls this function), so the two cannot disagree.
    """
    return min(float(grasp_width_m) + PRE_GRASP_EXTRA_OPENING_M, GRIPPER_MAX_WIDTH_M)


def commanded_force_n(youngs_modulus_pa: float, finger_force_n: float = 0.0) -> float:
    """The grasp's own force (its model's label rule) when it carries one (> 0), else the legacy rule of E;
    within the hand's rating either way."""
    f = float(finger_force_n)
    if not math.isfinite(f) or f < 0.0:
        raise GripperRuleError(f"grasp force must be a finite number of N >= 0 (0: the modulus rule), got {f}")
    return min(f, GRIPPER_MAX_FORCE_N) if f > 0.0 else grasp_force_n(youngs_modulus_pa)


def grasp_command(youngs_modulus_pa: float, grasp_width_m: float, finger_force_n: float = 0.0) -> GraspCommand:
    """The full gripper plan for a grasp of predicted opening `grasp_width_m` on a material E; finger_force_n:
    the force the grasp carries (0: the modulus rule's)."""
    w = float(grasp_width_m)
    if not math.isfinite(w) or w <= 0.0:
        raise GripperRuleError(f"grasp width must be a positive number of metres, got {w}")
    if w > GRIPPER_MAX_WIDTH_M:
        raise GripperRuleError(f"grasp width {w * 1000:.1f} mm exceeds the hand's maximum opening "
                               f"{GRIPPER_MAX_WIDTH_M * 1000:.0f} mm")
    force = commanded_force_n(youngs_modulus_pa, finger_force_n)
    soft = youngs_modulus_pa <= MAX_SOFT_BODY_YOUNGS_MODULUS_PA
    pre_open = pre_grasp_opening_m(w)
    width = min(w, pre_open)
    return GraspCommand(
        pre_open_width_m=pre_open,
        width_m=width,
        epsilon_inner_m=max(0.0, width - MISSED_WIDTH_M),
        epsilon_outer_m=pre_open - width,
        speed_mps=SOFT_CLOSING_SPEED_MPS if soft else RIGID_CLOSING_SPEED_MPS,
        force_n=force,
    )
