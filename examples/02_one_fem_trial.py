"""Run one FEM grasp trial in PyBullet and print its label: the generator's trial, as datasets/fem_v5 was made.

    .venv/bin/python examples/02_one_fem_trial.py                     # a soft 5 x 3 x 4 cm box (2e5 Pa), ~20 CPU-s
    .venv/bin/python examples/02_one_fem_trial.py --modulus-pa 2e9    # the same box rigid, ~1 CPU-s

The box rests on the table at the origin; the fingers close across its 3 cm side, 1.5 cm off its centre, 2 cm
up. The trial squeezes, picks it up and shakes it in 16 directions (docs/dataset.md, "Trial protocols"); the label
is positive when the mean acceleration the grasp held is at least 25 m/s^2, negative when it was not picked up.
"""
import argparse
import math

from defgg_ros.constants import SHAKE_POSITIVE_THRESHOLD_MPS2
from defgg_ros.data.format import STATUS_LIFT_FAILED, STATUS_OK
from defgg_ros.sim import objects
from defgg_ros.sim.trial import TrialSettings, WorldGrasp, run_grasp_trial


def main():
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--object", default="box_small", help="an object of sim.objects (default box_small)")
    parser.add_argument("--modulus-pa", type=float, default=2e5, help="Young's modulus (Pa); >= 1e9 is rigid")
    args = parser.parse_args()

    spec = objects.ObjectSpec(objects.get_shape(args.object), args.modulus_pa)
    grasp = WorldGrasp(position_m=(0.015, 0.0, 0.02), yaw_rad=math.pi / 2, width_m=0.03)
    settings = TrialSettings.fast()                      # the generator's settings and its default protocol
    outcome = run_grasp_trial(spec, grasp, ("shake",), settings)

    print(f"{args.object} at {args.modulus_pa:g} Pa, protocol {settings.protocol.name}: status {outcome.status}, "
          f"finger force {outcome.grasp_force_n:.2f} N, {outcome.cpu_s:.1f} CPU s")
    if outcome.status == STATUS_LIFT_FAILED:
        print("label: negative (not picked up)")
    elif outcome.status == STATUS_OK:
        measured = [a for a, m in zip(outcome.shake_accels_mps2, outcome.shake_measured) if m]
        print(f"held acceleration (m/s^2) in the {len(measured)} directions measured: "
              + ", ".join(f"{a:.1f}" for a in measured)
              + ("" if len(measured) == len(outcome.shake_accels_mps2) else " (the rest skipped: label decided)"))
        mean = outcome.shake_mean_mps2
        verdict = "positive" if mean >= SHAKE_POSITIVE_THRESHOLD_MPS2 else "negative"
        print(f"label: {verdict} (mean {mean:.1f} m/s^2, threshold {SHAKE_POSITIVE_THRESHOLD_MPS2:g})")
    else:
        print(f"no label: a simulation failure ({outcome.note})")


if __name__ == "__main__":
    main()
