"""Stiffness by squeezing in the simulated cell (issue 49 item 4): how close defgg_ros/squeeze.py's modulus
estimate comes to the true Young's modulus of the cell's FEM objects, and how repeatable it is.

  .venv/bin/python bench/bench_squeeze_stiffness.py [--repeats 3] [--moduli 2e4 6e4 2e5 6e5 2e6 2e9]

Jig (not the executor's sequence): the arm is set at a top-down grasp at half the object's height, then the
hand grasps at squeeze.GENTLE_FORCES_N, then at FIRM_FORCES_N while squeeze.needs_firmer says the compression
is not resolved; the opening is read 0.2 s after each grasp stopped. Each repeat turns the object (yaw 0, 0.3,
0.6 rad ...). Prints per object and modulus the estimate (median over repeats), its ratio to the truth, the
repeats' spread (max/min) and the force-compression slope. No machine compliance is taken out (see the
printout's last lines for why). The figures go into docs/real_cell.md ("Stiffness by squeezing").
"""
from __future__ import annotations

import argparse
import statistics
import sys
from dataclasses import replace
from pathlib import Path

import numpy as np
import pybullet as p

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from defgg_ros.control.kinematics import PandaKinematics  # noqa: E402
from defgg_ros.sim.cell.sim_cell import SimCell  # noqa: E402
from defgg_ros.sim.scene_spec import load_scene  # noqa: E402
from defgg_ros.squeeze import (  # noqa: E402
    FIRM_FORCES_N,
    GENTLE_FORCES_N,
    SqueezeReading,
    estimate_modulus,
    needs_firmer,
)

WIDTH_RESOLUTION_M = 1e-5       # the simulated hand's opening is exact to well below this
# (size along the closing axis, across it, height) m, FEM cell size m
BOXES = {"cube_5cm": ((0.05, 0.05, 0.05), 0.025), "slab_4x6x3": ((0.04, 0.06, 0.03), 0.02),
         "block_6x4.5x4": ((0.06, 0.045, 0.04), 0.03), "thin_3x5x5": ((0.03, 0.05, 0.05), 0.025)}
KIN = PandaKinematics()


def squeeze_once(size_m, cell_m, modulus_pa, yaw_rad) -> list:
    scene = load_scene(ROOT / "sim_bringup" / "scenes" / "soft_box.yaml")
    obj = replace(scene.objects[0], youngs_modulus_pa=modulus_pa, size_m=tuple(size_m), fem_cell_size_m=cell_m,
                  yaw_rad=yaw_rad, mass_kg=0.05)
    cell = SimCell(replace(scene, objects=[obj]))
    try:
        position, _ = cell.object_poses()[0]
        ik, _ = KIN.top_down_ik((position[0], position[1], size_m[2] / 2), yaw_rad)
        for joint, q in zip(cell.arm_joints, ik.q_rad):
            p.resetJointState(cell.robot, joint, q, 0.0, physicsClientId=cell.client)
        cell.tracker = type(cell.tracker)(np.asarray(ik.q_rad))
        cell.advance(0.3)
        readings = []
        for force in GENTLE_FORCES_N + FIRM_FORCES_N:
            if force in FIRM_FORCES_N and not needs_firmer(readings, WIDTH_RESOLUTION_M):
                break   # resolved at gentle forces: no need to squeeze harder
            cell.gripper_grasp(0.0, 0.08, 0.08, 0.02, force)
            for _ in range(500):
                if cell.advance(0.01):
                    break
            cell.advance(0.2)
            readings.append(SqueezeReading(force, cell.gripper_width_m()))
        return readings
    finally:
        cell.close()


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--repeats", type=int, default=3)
    parser.add_argument("--moduli", type=float, nargs="+", default=[2e4, 6e4, 2e5, 6e5, 2e6, 2e9])
    parser.add_argument("--objects", nargs="+", default=list(BOXES), choices=list(BOXES))
    args = parser.parse_args(argv)
    print(f"{'object':15s} {'E true':>8s} {'E est':>9s} {'ratio':>6s} {'spread':>7s} {'k N/m':>8s}  verdict")
    ratios = []
    for name in args.objects:
        size_m, cell_m = BOXES[name]
        for modulus in args.moduli:
            estimates = []
            for r in range(args.repeats):
                readings = squeeze_once(size_m, cell_m, modulus, 0.3 * r)
                estimates.append(estimate_modulus(readings, size_m[1], size_m[2],
                                                  width_resolution_m=WIDTH_RESOLUTION_M))
            values = [e.youngs_modulus_pa for e in estimates]
            median = statistics.median(values)
            ratio = median / modulus
            spread = max(values) / min(values)
            if modulus < 1e7:
                ratios.append(ratio)
            verdict = "rigid" if all(e.rigid for e in estimates) else \
                ">= bound" if any(e.lower_bound for e in estimates) else ""
            print(f"{name:15s} {modulus:8.0e} {median:9.2e} {ratio:6.2f} {spread:7.2f} "
                  f"{statistics.median(e.stiffness_npm for e in estimates):8.0f}  {verdict}", flush=True)
    if ratios:
        print(f"soft objects (E < 1e7 Pa): estimate / truth {min(ratios):.2f} .. {max(ratios):.2f}, "
              f"{sum(1 / 3 <= r <= 3 for r in ratios)} of {len(ratios)} within a factor 3")
    return 0


if __name__ == "__main__":
    sys.exit(main())
