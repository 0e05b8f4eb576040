"""The force a simulated grasp presses an FEM object with, against the force it was asked for (issue 49).

  .venv/bin/python bench/bench_fem_grasp_force.py [--forces 1 2 5 10 20] [--trial-forces 0.5 1 2 4] [--no-trials]
      [--drive-speeds 0.005 0.02 0.06]

PyBullet's deformable contact takes the momentum of a finger driven at a speed (POSITION_ or VELOCITY_CONTROL with
a force limit) each step, so such a finger presses an FEM body with about 2 m v / dt, whatever force it may use;
a rigid body gets the force limit. franka_gripper's grasp holds its force (docs/real_cell.md, "Grasp force on FEM
objects"). Two measurements:
1. The simulated cell's hand (the squeeze bench's jig, the 5 cm cube at 2e5 Pa, closing at 0.02 m/s as the squeeze
   and a soft pick do): the opening at each force, with the cell's drive (force
   control once on the object) and with the speed-driven drive it had before 2026-11-30. With --drive-speeds:
   the speed-driven hand closing at each speed with the largest force asked, and the force the pressing hand
   needs for the same opening (interpolated on the pressing column): what the old drive really pressed with.
2. The training trials' hand (defgg_ros/sim/hand.py: each finger a velocity drive at the protocol's close speed
   with the force as its limit): fem_v5's box_flat trial at each FEM modulus, closed with each --trial-forces
   force, the fingers' mean force after the close (the object sees the mean: the fingers are geared); then how many
   of fem_v5's FEM trials asked for more than what that modulus's trial pressed with at the largest force.
3. (--relabel N) What the pressing trial hand (the protocol's finger_drive "press": the cell's rule,
   sim/finger_press.py) changes: a seeded sample of N of those trials, and N of the others (the control: they
   asked no more than the hand pressed), re-run with it: labels that differ from the stored ones. The whole
   dataset: `defgg-datagen relabel` (datasets/fem_v5_press).
"""
from __future__ import annotations

import argparse
import random
import sys
from pathlib import Path

import pybullet as p

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))
sys.path.insert(0, str(ROOT / "bench"))

import bench_pad_contact_stiffness as pad_bench  # noqa: E402
import bench_squeeze_stiffness as squeeze_bench  # noqa: E402

from defgg_ros.data import datagen  # noqa: E402
from defgg_ros.data.format import TrialRecord  # noqa: E402
from defgg_ros.data.relabel import relabel_job  # noqa: E402
from defgg_ros.sim import trial as trial_mod  # noqa: E402
from defgg_ros.sim.cell.sim_cell import FINGER_JOINT_DAMPING_NSPM  # noqa: E402

SQUEEZE_SPEED_MPS = 0.02
TRIAL_OBJECT = "box_flat"


def cell_squeeze(forces_n, pressing: bool) -> list:
    """[(force, opening mm)] of the cell's hand on the 2e5 Pa cube, closing on it force by force (the fingers'
    reported drive force is no measure: a pressed finger's drive switches while it jitters)."""
    with squeeze_bench.hand_drive("pressing" if pressing else "speed-driven"):
        return _squeeze_cube(forces_n)


def _squeeze_cube(forces_n, speed_mps: float = SQUEEZE_SPEED_MPS) -> list:
    rows = []
    with squeeze_bench.jig(squeeze_bench.scene_object("cube_5cm", 2e5, 0.0)) as cell:
        for force in forces_n:
            cell.gripper_grasp(0.0, 0.08, 0.08, speed_mps, force)
            for _ in range(500):
                if cell.advance(0.01):
                    break
            cell.advance(0.5)
            rows.append((force, cell.gripper_width_m() * 1e3))
    return rows


def speed_driven_opening_mm(speed_mps: float, force_n: float) -> float:
    """The speed-driven hand's opening on the 2e5 Pa cube after one grasp at this speed and force."""
    with squeeze_bench.hand_drive("speed-driven"):
        return _squeeze_cube([force_n], speed_mps)[0][1]


def equivalent_force_n(opening_mm: float, pressed: list) -> float | None:
    """The force the pressing hand needs for this opening, linear between the rows of `pressed` ([(N, mm)], the
    opening falling with the force); None outside them."""
    for (f0, w0), (f1, w1) in zip(pressed, pressed[1:]):
        if min(w0, w1) <= opening_mm <= max(w0, w1) and w0 != w1:
            return f0 + (f1 - f0) * (w0 - opening_mm) / (w0 - w1)
    return None


def trial_pressed_n(record: dict, force_n: float) -> float:
    """The trial hand's mean finger force after its close on `record`'s object with `force_n` asked."""
    init, hold = trial_mod._Trial.__init__, trial_mod._Trial.hold_fingers_for_tests
    found = []

    def forced_init(self, *args, **kwargs):
        init(self, *args, **kwargs)
        self.force_n = force_n

    def measure(self):
        found.append(sum(self.hand.finger_forces_n()) / 2)
        raise trial_mod._Abort("measured", "the bench stops here")
    trial_mod._Trial.__init__, trial_mod._Trial.hold_fingers_for_tests = forced_init, measure
    try:
        datagen.run_trial_job(datagen.job_from_record(TrialRecord.from_json(record)))
    finally:
        trial_mod._Trial.__init__, trial_mod._Trial.hold_fingers_for_tests = init, hold
    if not found:
        raise RuntimeError(f"the trial of {record['object_name']} ended before its close")
    return found[0]


def ball_squeezes(damping_nspm: float, yaw_rad: float) -> tuple[list, list]:
    """--ringing: the 2e5 Pa ball in the jig, the pressing hand with this finger damping: each grasp's time to stop
    (s; None: timed out) and the 0.5 N steps (mm)."""
    stops, openings = [], []
    with squeeze_bench.jig(squeeze_bench.scene_object("common_ball", 2e5, yaw_rad)) as cell:
        for joint in cell.finger_joints:
            p.changeDynamics(cell.robot, joint, jointDamping=damping_nspm, physicsClientId=cell.client)
        for force in (0.5, 1.0, 1.5, 2.0):
            cell.gripper_grasp(0.0, 0.08, 0.08, SQUEEZE_SPEED_MPS, force)
            start_s, outcome = cell.time_s, []
            for _ in range(600):
                outcome = cell.advance(0.01)
                if outcome:
                    break
            stops.append(round(cell.time_s - start_s, 2) if outcome and outcome[0][1].success else None)
            openings.append(cell.gripper_width_m() * 1e3)
    return stops, [round(a - b, 2) for a, b in zip(openings, openings[1:])]


def relabel_with_pressing_hand(records: list) -> list:
    """(stored label, new label) of each record re-run with the pressing trial hand (finger_drive "press")."""
    out = []
    for stored in records:
        new = datagen.run_trial_job(relabel_job(stored, {"finger_drive": "press"}))
        out.append((stored.get("label"), new.get("label")))
        print(f"   {stored['object_name']:18s} {stored['youngs_modulus_pa']:.0e} Pa "
              f"{stored['grasp_force_n']:.2f} N: label {stored.get('label')} -> {new.get('label')}", flush=True)
    return out


def fem_trials() -> list:
    """fem_v5's simulated (status ok) FEM trials."""
    return [row for row in pad_bench.stored_trials()
            if row["youngs_modulus_pa"] < 1e7 and row["status"] == "ok"]


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0], epilog=__doc__.split("\n\n", 1)[1],
                                     formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--forces", type=float, nargs="+", default=[1.0, 2.0, 5.0, 10.0, 20.0],
                        help="part 1: grasp forces, N (franka_gripper's grasp force)")
    parser.add_argument("--trial-forces", type=float, nargs="+", default=[0.5, 1.0, 2.0, 4.0],
                        help="part 2: forces the trial hand is asked for, N")
    parser.add_argument("--no-trials", action="store_true", help="part 1 only")
    parser.add_argument("--drive-speeds", type=float, nargs="+", default=[], metavar="M_PER_S",
                        help="part 1: also the speed-driven hand at these closing speeds (m/s; the squeeze and a "
                             "soft pick 0.02, a rigid pick 0.05-0.06), with the largest --forces asked")
    parser.add_argument("--ringing", action="store_true",
                        help="also: the FEM ball squeezed by the pressing hand with and without the fingers' damping "
                             "(sim_cell.FINGER_JOINT_DAMPING_NSPM): time to stop and steps")
    parser.add_argument("--relabel", type=int, default=0, metavar="N",
                        help="part 3: re-run N of the trials that asked for more, and N of the others, with a "
                             "pressing trial hand (~20-40 CPU s each)")
    parser.add_argument("--seed", type=int, default=0, help="part 3's sample")
    args = parser.parse_args(argv)
    if any(f <= 0 for f in args.forces + args.trial_forces):
        parser.error("forces must be > 0 N")
    if any(not 0 < v <= 0.1 for v in args.drive_speeds):
        parser.error("--drive-speeds must be in (0, 0.1] m/s (the hand's opening speed)")
    args.forces = sorted(args.forces)

    print(f"1. The cell's hand on the 5 cm cube at 2e5 Pa, closing at {SQUEEZE_SPEED_MPS} m/s", flush=True)
    pressed, driven = cell_squeeze(args.forces, True), cell_squeeze(args.forces, False)
    print("   asked N | opening mm: pressing (the cell) | speed-driven (before 2026-11-30)")
    for (force, w_new), (_, w_old) in zip(pressed, driven):
        print(f"   {force:7.2f} | {w_new:8.3f} | {w_old:8.3f}")
    for speed in args.drive_speeds:
        opening = speed_driven_opening_mm(speed, args.forces[-1])
        found = equivalent_force_n(opening, pressed)
        said = f"{found:.1f} N" if found is not None else f"outside {args.forces[0]:g}-{args.forces[-1]:g} N"
        print(f"   speed-driven at {speed:g} m/s, {args.forces[-1]:g} N asked: {opening:.3f} mm, as the pressing "
              f"hand at {said}", flush=True)
    if args.ringing:
        for damping in (FINGER_JOINT_DAMPING_NSPM, 0.0):
            for yaw in (0.0, 2.0):
                stops, steps = ball_squeezes(damping, yaw)
                print(f"   the ball, yaw {yaw}, finger damping {damping:g} N s/m: grasps stopped after {stops} s "
                      f"(None: timed out), steps {steps} mm", flush=True)
    if args.no_trials:
        return 0

    trials = fem_trials()
    print(f"2. The trial hand (fem_v5's {TRIAL_OBJECT} trial at each modulus): mean finger force after the close",
          flush=True)
    ceilings = {}
    for modulus in sorted({row["youngs_modulus_pa"] for row in trials}):
        record = next(row for row in trials if row["object_name"] == TRIAL_OBJECT
                      and row["youngs_modulus_pa"] == modulus)
        found = [trial_pressed_n(record, force) for force in args.trial_forces]
        ceilings[modulus] = found[-1]
        print(f"   {modulus:.0e} Pa: " + ", ".join(f"{a:g} N -> {f:.2f} N" for a, f in zip(args.trial_forces, found)),
              flush=True)
    above = [row for row in trials if row["grasp_force_n"] > 1.05 * ceilings[row["youngs_modulus_pa"]]]
    print(f"   fem_v5's FEM trials asking more than 1.05 x their modulus's pressed force at "
          f"{args.trial_forces[-1]:g} N: {len(above)} of {len(trials)}; "
          + ", ".join(f"{m:.0e} Pa {sum(r['youngs_modulus_pa'] == m for r in above)} of "
                      f"{sum(r['youngs_modulus_pa'] == m for r in trials)}" for m in sorted(ceilings)))
    if args.relabel > 0:
        below = [row for row in trials if row not in above]
        rng = random.Random(args.seed)
        for name, group in (("asked for more", above), ("control", below)):
            sample = rng.sample(group, min(args.relabel, len(group)))
            print(f"3. {len(sample)} trials that {name if name != 'control' else 'asked no more (control)'}, "
                  "re-run with a pressing trial hand:", flush=True)
            found = relabel_with_pressing_hand(sample)
            differ = sum(a != b for a, b in found)
            print(f"   {name}: {differ} of {len(found)} labels differ "
                  f"({sum(a is False and b is True for a, b in found)} negative -> positive)", flush=True)
    return 0


if __name__ == "__main__":
    sys.exit(main())
