"""Does the cell count a hand-FEM contact once or twice? Both sides of it, pressed and held.

    .venv/bin/python bench/bench_fem_contact_sides.py

The closed hand presses into the FEM box of soft_box.yaml (TCP at 3 cm, then 2 cm above the table) and is held;
over 200 control periods it averages the force on the robot from the contacts PyBullet reports with the robot as
body A ("robot side"), with the FEM box as body A ("FEM side", mirrored), their sum (what SimCell.external_wrench
reports: objects.hand_contact_forces takes both queries), and what the box's own balance says the hand pushes with
(its other contacts, the table's, plus its weight; a dynamic FEM body, so a rough check). Nothing is asserted.
"""
import argparse
import sys
from pathlib import Path

import numpy as np
import pybullet as p

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from defgg_ros.control.kinematics import PandaKinematics  # noqa: E402
from defgg_ros.sim.cell import objects as cell_objects  # noqa: E402
from defgg_ros.sim.cell.sim_cell import CellSettings, SimCell  # noqa: E402
from defgg_ros.sim.scene_spec import load_scene  # noqa: E402

GRAVITY_MPS2 = 9.81


def sides(cell, body: int) -> tuple:
    """(force on the robot, robot side; the same, FEM side; force on the box from everything but the robot)."""
    links = set(cell.hand_links)
    robot_side, fem_side, others = np.zeros(3), np.zeros(3), np.zeros(3)
    for c in p.getContactPoints(bodyA=cell.robot, physicsClientId=cell.client):
        if c[3] in links and c[2] == body:
            robot_side += cell_objects._force_on_a(c)
    for c in p.getContactPoints(bodyA=body, physicsClientId=cell.client):
        if c[2] == cell.robot and c[4] in links:
            fem_side -= np.array(cell_objects._force_on_a(c))
        elif c[2] != cell.robot:
            others += cell_objects._force_on_a(c)
    return robot_side, fem_side, others


def main():
    argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter).parse_args()
    cell = SimCell(load_scene(ROOT / "sim_bringup" / "scenes" / "soft_box.yaml"), CellSettings(soft_always_active=True))
    try:
        kinematics, q0 = PandaKinematics(), cell.joint_state().positions[:7].copy()
        xyz, _ = cell.object_poses()[0]
        body, mass_kg = next(iter(cell._soft.values())).body, cell.scene.objects[0].mass_kg
        print("# force on the robot (N, x y z), mean of 200 periods held")
        for tcp_z_m in (0.03, 0.02):
            solution, _ = kinematics.top_down_ik([xyz[0] + 0.01, xyz[1], tcp_z_m], 0.3, q0)
            cell.gripper_move(0.0, 0.05)
            cell.command_trajectory([(2.0, solution.q_rad, None, None)], cell.time_s)
            cell.advance(3.5)
            samples = []
            for _ in range(200):
                cell.advance(0.001)
                samples.append(sides(cell, body))
            robot_side, fem_side, others = (np.mean([s[i] for s in samples], axis=0) for i in range(3))
            balance = others + np.array([0.0, 0.0, -GRAVITY_MPS2 * mass_kg])
            reported = cell.external_wrench()[0]
            print(f"TCP z {tcp_z_m:.2f} m: robot side {np.round(robot_side, 1)}, FEM side {np.round(fem_side, 1)}, "
                  f"external_wrench now {np.round(reported, 1)}, the box's balance {np.round(balance, 1)}")
    finally:
        cell.close()


if __name__ == "__main__":
    main()
