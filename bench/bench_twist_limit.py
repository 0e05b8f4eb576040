"""Why no grasp holds the twist task: an evaluation's twist trials re-run with one knob changed.

    .venv/bin/python bench/bench_twist_limit.py results/sim_v4/superseded/twist_ramp0.5s_trials.jsonl
    .venv/bin/python bench/bench_twist_limit.py results/sim_v4 --moduli 2e9 2e6 --variants as_eval all_axes

Every best-grasp twist trial of an evaluation's results (a folder's trials.jsonl, or a .jsonl file)
at the chosen moduli (same object, pose and grasp) is run again under each variant, all of them
derived from the settings the trials were recorded with:

  as_eval      the recorded settings: the re-run must reproduce the recorded value (determinism)
  all_axes     as recorded but no stop at the first failed axis: the held angular acceleration about every hand axis
  force_xN     the label rule's grip force times N (at most the Franka Hand's 70 N)
  spin_MU      torsional (spinning) friction MU on the finger pads and the object (PyBullet's default
               is 0, and it combines the two bodies' values by product)
  ramp_T       the angular acceleration ramped to the limit in T s instead of 0.5 s (the hand reaches
               only 500 * T / 2 rad/s instead of 125 rad/s)
  osc_W        the angular acceleration oscillates at W rad/s under the same ramped amplitude (the
               evaluation's twist since 2026-11-25: osc_40; the hand spins at most ~500 / W rad/s)
  track        the palm follows its target more tightly: constraint ERP 1 (default 0.2) and the target
               moved every 1 ms instead of every 5 ms
  track_all    track + spin_0.01 + force_x4

Besides the held values it records, at each axis's loss, how far the simulated hand itself came
apart: the finger opening's largest rise above the grasp's (mm; the fingers are force-limited and
should not open) and the palm's largest distance from its commanded pose (mm).

The grip force, the friction and the palm's tracking are changed here, for this measurement only:
the trial code, the generator and the evaluation keep the label rule (sim/trial.py) and the hand.
Rigid bodies (2e9 Pa, the default) cost ~1 s CPU per trial and isolate the grip from the FEM.
Prints per variant: trials held at 500 rad/s^2 about every axis, and the median held value per axis.
"""
from __future__ import annotations

import argparse
import contextlib
import statistics
import sys
from pathlib import Path

import numpy as np
import pybullet as p

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from defgg_ros.constants import GRIPPER_MAX_FORCE_N, TWIST_ACCEL_LIMIT_RADPS2  # noqa: E402
from defgg_ros.evaluation.sources import named_set  # noqa: E402
from defgg_ros.evaluation.store import read_results, results_path  # noqa: E402
from defgg_ros.sim import hand as hand_mod  # noqa: E402
from defgg_ros.sim import trial as trial_mod  # noqa: E402
from defgg_ros.sim import world  # noqa: E402
from defgg_ros.sim.protocol import TrialProtocol  # noqa: E402
from defgg_ros.sim.trial import TWIST_AXES, TrialSettings, WorldGrasp, run_grasp_trial  # noqa: E402

DEFAULT_VARIANTS = ("as_eval", "all_axes", "force_x4", "force_x15", "spin_0.01", "spin_0.05", "track", "track_all",
                    "ramp_0.2", "ramp_0.1", "ramp_0.05", "osc_20", "osc_40", "osc_80")
OPENED_MM = 5.0
TRACK_ERP = 1.0
TRACK_UPDATE_S = 0.001
AXIS_NAMES = ("+x (pad axis)", "-x", "+y", "-y", "+z (approach)", "-z")


@contextlib.contextmanager
def _grip(force_scale: float = 1.0, spinning_friction: float | None = None, erp: float | None = None):
    """The trial's grip force rule, pad/object friction and palm tracking, changed for one trial."""
    rule, create, load = TrialProtocol.finger_force_n, hand_mod.create_hand, trial_mod.objects.load_object

    def scaled_rule(protocol, youngs_modulus_pa, mass_kg):
        return min(rule(protocol, youngs_modulus_pa, mass_kg) * force_scale, GRIPPER_MAX_FORCE_N)

    def create_changed(client, *args, **kwargs):
        hand = create(client, *args, **kwargs)
        if spinning_friction is not None:
            for link in hand_mod.Hand.FINGER_LINKS:
                p.changeDynamics(hand.body_id, link, spinningFriction=spinning_friction, physicsClientId=client)
        if erp is not None:
            p.changeConstraint(hand.constraint_id, erp=erp, physicsClientId=client)
        return hand

    def load_changed(client, *args, **kwargs):
        obj = load(client, *args, **kwargs)
        for body in obj.body_ids:
            p.changeDynamics(body, -1, spinningFriction=spinning_friction, physicsClientId=client)
        return obj

    TrialProtocol.finger_force_n, hand_mod.create_hand = scaled_rule, create_changed
    if spinning_friction is not None:
        trial_mod.objects.load_object = load_changed
    try:
        yield
    finally:
        TrialProtocol.finger_force_n, hand_mod.create_hand, trial_mod.objects.load_object = rule, create, load


class HandIntegrity:
    """Largest finger-opening rise and palm pose error seen by the trial's held() checks during the twist."""

    def __init__(self):
        self.opening_rise_mm, self.palm_error_mm, self.last = [], [], None

    @contextlib.contextmanager
    def watching(self):
        held, move_to = trial_mod._Trial.held, hand_mod.Hand.move_to
        state = {}

        def tracked_move_to(hand, pose):
            state["target"] = pose
            move_to(hand, pose)

        def watched_held(trial):
            hand = trial.hand
            if "opening0" not in state:
                state["opening0"] = hand.finger_opening_m()
            if "target" in state:
                state["rise"] = max(state.get("rise", 0.0), hand.finger_opening_m() - state["opening0"])
                state["error"] = max(state.get("error", 0.0),
                                     float(np.linalg.norm(hand.pose()[:3, 3] - state["target"][:3, 3])))
            return held(trial)

        trial_mod._Trial.held, hand_mod.Hand.move_to = watched_held, tracked_move_to
        try:
            yield
        finally:
            trial_mod._Trial.held, hand_mod.Hand.move_to = held, move_to
            self.last = (1000 * state["rise"], 1000 * state["error"]) if "rise" in state else None

    def keep_last(self) -> None:
        """Count the trial just watched (only trials that reached the twist are counted)."""
        if self.last is not None:
            self.opening_rise_mm.append(self.last[0])
            self.palm_error_mm.append(self.last[1])


def variant_setup(name: str, eval_settings: TrialSettings):
    """(TrialSettings, grip context) of a variant name."""
    all_axes = eval_settings.with_fields(twist_fail_below_radps2=None)
    tracked = all_axes.with_fields(check_every_s=TRACK_UPDATE_S)
    if name == "as_eval":
        return eval_settings, _grip()
    if name == "all_axes":
        return all_axes, _grip()
    if name.startswith("force_x"):
        return all_axes, _grip(force_scale=float(name.removeprefix("force_x")))
    if name.startswith("spin_"):
        return all_axes, _grip(spinning_friction=float(name.removeprefix("spin_")))
    if name.startswith("osc_"):
        return all_axes.with_fields(twist_oscillation_radps=float(name.removeprefix("osc_"))), _grip()
    if name.startswith("ramp_"):
        return all_axes.with_fields(twist_ramp_time_s=float(name.removeprefix("ramp_"))), _grip()
    if name == "track":
        return tracked, _grip(erp=TRACK_ERP)
    if name == "track_all":
        return tracked, _grip(force_scale=4.0, spinning_friction=0.01, erp=TRACK_ERP)
    raise SystemExit(f"unknown variant {name!r}; known: as_eval, all_axes, force_xN, spin_MU, ramp_T, osc_W, track, "
                     "track_all")


def rerun(record: dict, settings: TrialSettings, grip, client: int):
    """The recorded trial's object, pose and grasp under `settings` and `grip`."""
    (obj,) = named_set(record["object_set"], moduli_pa=(record["youngs_modulus_pa"],), only=[record["object"]])
    part0 = record["part_moduli_pa"][0] if len(record["part_moduli_pa"]) > 1 else None
    g = record["grasp"]
    with grip:
        return run_grasp_trial(obj.spec(record["youngs_modulus_pa"], part0),
                               WorldGrasp(tuple(g["position_m"]), g["yaw_rad"], g["width_m"]),
                               tests=("twist",), settings=settings, client=client,
                               object_yaw_rad=record["object_yaw_rad"])


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("results", help="evaluation folder with trials.jsonl, or a trials .jsonl file (twist trials)")
    ap.add_argument("--moduli", nargs="+", type=float, default=[2e9], help="Young's moduli to re-run (Pa)")
    ap.add_argument("--variants", nargs="+", default=list(DEFAULT_VARIANTS))
    ap.add_argument("--model", default=None, help="only this model's trials (default: every model's)")
    args = ap.parse_args(argv)
    path = Path(args.results) if args.results.endswith((".jsonl", ".jsonl.gz")) else results_path(args.results)
    records = [r for r in read_results(path)
               if r["task"] == "twist" and r["experiment"] == "main" and r.get("grasp") and r["rank"] == 0
               and r.get("reused_from") is None and any(abs(r["youngs_modulus_pa"] - e) < 1 for e in args.moduli)
               and (args.model is None or r["model"] == args.model)]
    if not records:
        raise SystemExit(f"no twist trials at {args.moduli} Pa in {args.results}")
    print(f"{len(records)} recorded twist trials at E = {', '.join(f'{e:.0e}' for e in args.moduli)} Pa; "
          f"limit {TWIST_ACCEL_LIMIT_RADPS2:.0f} rad/s^2 about each of {len(TWIST_AXES)} hand axes")
    client = world.connect()
    base = TrialSettings.from_record(records[0]["trial_settings"])
    for name in args.variants:
        held_all, lifted, reproduced, per_axis, forces = 0, 0, 0, [[] for _ in TWIST_AXES], set()
        integrity = HandIntegrity()
        for r in records:
            settings, grip = variant_setup(name, base)   # a fresh context per trial
            with integrity.watching():
                out = rerun(r, settings, grip, client)
            forces.add(round(out.grasp_force_n, 1))
            if out.status != "ok":
                continue
            integrity.keep_last()
            lifted += 1
            values = out.twist_accels_radps2
            measured = out.twist_measured
            for k, (v, m) in enumerate(zip(values, measured)):
                if m:
                    per_axis[k].append(v)
            held_all += all(m and v >= TWIST_ACCEL_LIMIT_RADPS2 * (1 - 1e-6) for v, m in zip(values, measured))
            if name == "as_eval" and r.get("accels"):
                reproduced += abs(values[0] - r["accels"][0]) < 1e-6
        medians = " ".join(f"{a}: {statistics.median(v):.0f}" if v else f"{a}: –"
                           for a, v in zip(AXIS_NAMES, per_axis))
        extra = f", first axis reproduces the record in {reproduced}/{lifted}" if name == "as_eval" else ""
        grip_n = "/".join(map(str, sorted(forces)))
        print(f"{name:>10}: grip {grip_n} N/finger, {lifted}/{len(records)} lifted, held all axes "
              f"{held_all}/{lifted}{extra}; median held (rad/s^2) {medians}", flush=True)
        rise, err = integrity.opening_rise_mm, integrity.palm_error_mm
        if rise:
            print(f"{'':>12}hand during the twist: fingers opened > {OPENED_MM:.0f} mm beyond the grasp in "
                  f"{sum(x > OPENED_MM for x in rise)}/{len(rise)} trials (median {statistics.median(rise):.1f}, "
                  f"max {max(rise):.1f} mm); palm off its target by median {statistics.median(err):.1f}, "
                  f"max {max(err):.1f} mm", flush=True)
    p.disconnect(client)
    return 0


if __name__ == "__main__":
    sys.exit(main())
