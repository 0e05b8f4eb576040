"""The simulated hand's compliance is the rigid-body contact's: what a stiff pad contact would change (issue 49).

  .venv/bin/python bench/bench_pad_contact_stiffness.py [--stiffness-npm 1e6] [--trials 300]

The squeeze's hand calibration (docs/squeeze.md) takes out ~74-85 um/N measured on a rigid block; in PyBullet that
is the rigid-body contact's own yield (the finger links are rigid), which an FEM object's contact does not have, so
the 2e6 Pa rows are over-corrected. Three measurements of giving the Panda's pads a stiff contact
(changeDynamics contactStiffness, damping 1e3 N s/m):
1. Squeezes in the cell (the squeeze bench's jig): the rigid 5 cm block and the FEM 5 cm block at 2e5 and 2e6 Pa,
   engine default vs stiff pads: the compliance (um/N) and whether the FEM readings moved at all.
2. The labels: fem_v5's rigid (2e9 Pa) trials (models/train_data_fem_v5.tar.gz, a seeded sample) re-run with the
   trial hand's pads stiff, and, as the control for the trials' own sensitivity, with the pads' friction moved
   by 1e-6: labels that differ from the stored ones.
3. The held-out squeeze table (bench_squeeze_stiffness.py's stored FEM readings: the speed-driven hand's, --hand)
   estimated with the hand calibration the stiff pads give (the rigid block of 1., its compliance; the noise from
   four yaws). A row the stored file lacks is squeezed with the stiff pads into a scratch copy; the stored
   readings are not written.
4. (--rigid-objects) The 14 evaluation objects as rigid bodies (2e9 Pa) squeezed with the stiff pads, estimated
   with the stiff calibration of 1. as the executor does (the "section" column's law): are they still read rigid?
   With --trials 0 and --rigid-objects, parts 2 and 3 are skipped (part 3 is --what-if-hand's table).
Nothing here changes the shipped physics (docs/squeeze.md "The simulated cell's FEM contact").
"""
from __future__ import annotations

import argparse
import io
import json
import random
import shutil
import statistics
import sys
import tarfile
import tempfile
from pathlib import Path

import pybullet as p

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))
sys.path.insert(0, str(ROOT / "bench"))

import bench_squeeze_stiffness as squeeze_bench  # noqa: E402

from defgg_ros.data import datagen  # noqa: E402
from defgg_ros.data.format import TrialRecord  # noqa: E402
from defgg_ros.evaluation import cell_experiment  # noqa: E402
from defgg_ros.sim import hand as trial_hand  # noqa: E402
from defgg_ros.squeeze import HandCalibration, squeeze_slope_npm  # noqa: E402

DAMPING_NSPM = 1e3
LABELS = ROOT / "models" / "train_data_fem_v5.tar.gz"
STORED_READINGS = ROOT / "results" / "squeeze" / "readings.jsonl"     # part 3 reads a copy


def stiff_cell(stiffness_npm: float):
    """SimCell whose finger links get the stiff contact (None: the engine's default)."""
    original = squeeze_bench.SimCell

    def make(*args, **kwargs):
        cell = original(*args, **kwargs)
        if stiffness_npm:
            for joint in cell.finger_joints:
                p.changeDynamics(cell.robot, joint, contactStiffness=stiffness_npm, contactDamping=DAMPING_NSPM,
                                 physicsClientId=cell.client)
        return cell
    return make


def compliance_um_per_n(readings) -> float:
    return 1e6 / squeeze_slope_npm(readings)[0]


def squeezes(stiffness_npm: float) -> dict:
    """Part 1 (and the stiff calibration for part 3): readings per (object, modulus, yaw)."""
    squeeze_bench.SimCell = stiff_cell(stiffness_npm)
    out = {}
    for modulus, yaws in ((2e9, squeeze_bench.CALIBRATION_YAWS_RAD), (2e5, (0.0,)), (2e6, (0.0,))):
        for yaw in yaws:
            out[(modulus, yaw)] = squeeze_bench.squeeze_once(squeeze_bench.scene_object("cube_5cm", modulus, yaw))
    return out


def stored_trials(file_part: str = "") -> list:
    """fem_v5's stored trial records (models/train_data_fem_v5.tar.gz), from the trial files whose name holds
    `file_part` (e.g. "__E2e+09": the rigid ones), in the archive's order."""
    records = []
    with tarfile.open(LABELS) as tar:
        for member in tar.getmembers():
            if member.name.startswith("train_data/trials/") and file_part in member.name:
                text = io.TextIOWrapper(tar.extractfile(member), encoding="utf-8").read()
                records += [json.loads(line) for line in text.splitlines() if line.strip()]
    return records


def rigid_trials(n: int) -> list:
    """A seeded sample of fem_v5's stored 2e9 Pa trial records."""
    records = stored_trials("__E2e+09")
    records.sort(key=lambda r: r["trial_id"] if "trial_id" in r else (r["scene_id"], r["candidate_index"]))
    random.Random(0).shuffle(records)
    return records[:n]


def relabel(records: list, **dynamics) -> tuple[int, float]:
    """Labels that differ when the trial hand's pads get `dynamics`; the largest shake-mean change (m/s^2)."""
    original = trial_hand.create_hand

    def create(client, *args, **kwargs):
        hand = original(client, *args, **kwargs)
        for link in hand.FINGER_LINKS:
            p.changeDynamics(hand.body_id, link, physicsClientId=client, **dynamics)
        return hand
    trial_hand.create_hand = create
    try:
        flipped, largest = 0, 0.0
        for stored in records:
            new = datagen.run_trial_job(datagen.job_from_record(TrialRecord.from_json(stored)))
            flipped += new.get("label") != stored.get("label")
            if new.get("shake_mean_mps2") is not None and stored.get("shake_mean_mps2") is not None:
                largest = max(largest, abs(new["shake_mean_mps2"] - stored["shake_mean_mps2"]))
        return flipped, largest
    finally:
        trial_hand.create_hand = original


EVALUATION_OBJECTS = tuple(obj.name for obj in cell_experiment.OBJECTS)     # the cell experiment's 14


def rigid_verdicts(hand: HandCalibration, yaws=(0.0,)) -> tuple[int, int]:
    """Part 4: each evaluation object as a rigid body squeezed by the (stiff-padded) cell, printed; (rigid, n)."""
    rigid = total = 0
    for name in EVALUATION_OBJECTS:
        for yaw in yaws:
            spec = squeeze_bench.scene_object(name, 2e9, yaw)
            readings = squeeze_bench.squeeze_once(spec)
            try:
                estimate = squeeze_bench.estimates_of(readings, spec, hand, squeeze_bench.contacts_of(spec))["section"]
                verdict = "rigid" if estimate.rigid else f"{estimate.youngs_modulus_pa:.2g} Pa"
            except squeeze_bench.SqueezeError as error:
                estimate, verdict = None, f"refused: {error}"
            rigid += bool(estimate and estimate.rigid)
            total += 1
            print(f"   {name:16s} yaw {yaw:.1f}: {compliance_um_per_n(readings):7.1f} um/N -> {verdict}", flush=True)
    return rigid, total


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0], epilog=__doc__.split("\n\n", 1)[1],
                                     formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--stiffness-npm", type=float, default=1e6, help="the pads' contact stiffness, N/m")
    parser.add_argument("--trials", type=int, default=300, help="fem_v5 rigid trials re-run (0: skip part 2)")
    parser.add_argument("--rigid-objects", action="store_true",
                        help="part 4: the 14 evaluation objects as rigid bodies with the stiff pads (~2 min)")
    args = parser.parse_args(argv)
    default, stiff = squeezes(0.0), squeezes(args.stiffness_npm)
    print(f"1. squeezes, 0.5-2 N (then 10-20 N while unresolved); pads default | {args.stiffness_npm:.0e} N/m:")
    for key in default:
        moved = "identical" if default[key] == stiff[key] else "moved"
        print(f"   cube_5cm {key[0]:.0e} Pa yaw {key[1]:.1f}: {compliance_um_per_n(default[key]):6.1f} | "
              f"{compliance_um_per_n(stiff[key]):6.1f} um/N  (readings {moved})", flush=True)
    if args.trials:
        records = rigid_trials(args.trials)
        flips, largest = relabel(records, contactStiffness=args.stiffness_npm, contactDamping=DAMPING_NSPM)
        print(f"2. fem_v5 rigid trials re-run, labels differing: stiff pads {flips} of {len(records)} (shake mean "
              f"moved up to {largest:.1f} m/s^2)", flush=True)
        flips, largest = relabel(records, lateralFriction=1.0 + 1e-6)
        print(f"   control, pad friction +1e-6: {flips} of {len(records)} (up to {largest:.1f} m/s^2)", flush=True)
    rigid = [1e-6 * compliance_um_per_n(stiff[(2e9, yaw)]) for yaw in squeeze_bench.CALIBRATION_YAWS_RAD]
    hand = HandCalibration(1.0 / statistics.mean(rigid), statistics.stdev(rigid),
                           f"stiff pads {args.stiffness_npm:.0e} N/m, rigid cube_5cm at 4 yaws")
    if args.rigid_objects:
        print(f"4. the evaluation objects at 2e9 Pa (rigid bodies), stiff pads, {hand.describe()}:", flush=True)
        rigid, total = rigid_verdicts(hand)
        print(f"   read rigid: {rigid} of {total}", flush=True)
        if not args.trials:
            return 0
    print(f"3. the held-out FEM squeezes (stored readings) with {hand.describe()}:", flush=True)
    squeeze_bench.calibration = lambda path: hand
    # A row the stored file lacks is squeezed here with the stiff pads: into a copy, never the stored readings.
    with tempfile.TemporaryDirectory() as scratch:
        readings = Path(scratch) / "readings.jsonl"
        shutil.copy(STORED_READINGS, readings)
        return squeeze_bench.main(["--objects", "held_out", "--moduli", "2e4", "2e5", "2e6",
                                   "--readings", str(readings), "--hand", "speed-driven"])


if __name__ == "__main__":
    sys.exit(main())
