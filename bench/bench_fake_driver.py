"""Real-time factor of the simulated cell (the fake driver's core), with and without soft objects.

    .venv/bin/python bench/bench_fake_driver.py [--sim-seconds 2]

Cases (each: the arm follows a slow joint trajectory while the cell steps in
10 ms control periods, as the driver node does):
  rigid          rigid_box.yaml: the arm, table, bin and a rigid box (1 ms steps)
  soft-dormant   soft_box.yaml, hand far away: the soft box sleeps as a static mesh
  soft-active    soft_box.yaml with the soft box as an FEM body (27 nodes, 0.5 ms steps), resting on the table
  soft-grasped   the same, while the fingers squeeze it
  render         one 640x480 depth render (TinyRenderer), ms
Prints sim seconds per wall second and CPU ms per control period; the
machine is shared, so CPU time is the steadier figure.
"""
import argparse
import os
import sys
import time
from pathlib import Path

import numpy as np
import pybullet as p

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from defgg_ros.constants import PANDA_READY_Q_RAD  # noqa: E402
from defgg_ros.sim.cell.sim_cell import CellSettings, SimCell  # noqa: E402
from defgg_ros.sim.scene_spec import load_scene  # noqa: E402

SCENES = Path(__file__).resolve().parents[1] / "sim_bringup" / "scenes"
PERIOD_S = 0.01


def measure(cell, sim_seconds):
    wall0, cpu0 = time.perf_counter(), time.process_time()
    periods = int(round(sim_seconds / PERIOD_S))
    for _ in range(periods):
        cell.advance(PERIOD_S)
    wall, cpu = time.perf_counter() - wall0, time.process_time() - cpu0
    return sim_seconds / wall, sim_seconds / cpu, cpu / periods * 1e3


def sway(cell, seconds):
    q = np.array(PANDA_READY_Q_RAD)
    cell.command_trajectory([(seconds / 2, q + 0.1, None, None), (seconds, q, None, None)])


def grasp_soft(cell):
    xyz, _ = cell.object_poses()[0]
    quat = p.getQuaternionFromEuler([np.pi, 0, 0])
    q = p.calculateInverseKinematics(cell.robot, cell.tcp_link, list(xyz), quat, maxNumIterations=200,
                                     physicsClientId=cell.client)[:7]
    cell.command_trajectory([(1.0, q, None, None)])
    cell.advance(1.2)
    cell.gripper_grasp(0.05, 0.01, 0.01, 0.05, 10.0)
    cell.advance(0.3)


def main():
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--sim-seconds", type=float, default=2.0, help="simulated seconds per case")
    args = parser.parse_args()
    print(f"# bench_fake_driver: {args.sim_seconds} s of sim time per case, {os.cpu_count()} CPUs, "
          f"load {os.getloadavg()[0]:.1f}")
    print(f"{'case':<14} {'RTF (wall)':>10} {'RTF (CPU)':>10} {'CPU ms / 10 ms period':>22}  step")
    cases = [("rigid", "rigid_box.yaml", False, None), ("soft-dormant", "soft_box.yaml", False, None),
             ("soft-active", "soft_box.yaml", True, None), ("soft-grasped", "soft_box.yaml", True, grasp_soft)]
    for name, scene, active, prepare in cases:
        cell = SimCell(load_scene(SCENES / scene), CellSettings(soft_always_active=active))
        try:
            if prepare:
                prepare(cell)
            else:
                sway(cell, args.sim_seconds)
            rtf_wall, rtf_cpu, ms = measure(cell, args.sim_seconds)
            print(f"{name:<14} {rtf_wall:>10.2f} {rtf_cpu:>10.2f} {ms:>22.1f}  {cell.time_step_s * 1e3:.2f} ms")
            if name == "rigid":
                t0 = time.perf_counter()
                for _ in range(5):
                    cell.render_depth()
                print(f"{'render':<14} {(time.perf_counter() - t0) / 5 * 1e3:>10.0f} ms per 640x480 depth frame")
        finally:
            cell.close()


if __name__ == "__main__":
    main()
