"""How stiff the simulated arm is at the hand, against a Franka under franka_bringup's trajectory controller.

    .venv/bin/python bench/bench_hand_stiffness.py [--step-mm 0.5] [--depth-mm 3]

How hard does the simulated hand press when the arm's command goes a little below a rigid surface, with each of the
cell's arm drives (sim_cell.ARM_DRIVES: PyBullet's position motor, the cell's; franka's controller gains)?
The closed fingers' ends are lowered onto the top of rigid_box.yaml's block in steps of --step-mm, each held until the
arm is still; the force is the cell's external wrench (what franka_robot_state_broadcaster's topic carries),
averaged over the last 100 ms of each step. Its slope past the first contact is the arm's stiffness at the hand
along z (N/mm).

A real arm under `<robot_type>_arm_controller` (effort interface; constants.FRANKA_JTC_GAINS_PD, as in
sim_bringup/config/franka/controllers.yaml: p of 600, 600, 600, 600, 250, 150, 50 N*m/rad) is a joint spring of
those gains on top of the robot's own gravity compensation, so its stiffness at the TCP along z at the same joint
positions is 1 / (J K^-1 J^T)_zz (J the TCP's translational Jacobian, K the diagonal of p). That is the press a
given overshoot of the command makes, and what a force reflex (docs/franka_contract.md, "Robot errors") sees.
Nothing is asserted.
"""
import argparse
import sys
from pathlib import Path

import numpy as np
import pinocchio as pin

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from defgg_ros.constants import FRANKA_JTC_GAINS_PD, PANDA_FINGERTIP_BELOW_TCP_M  # noqa: E402
from defgg_ros.control.kinematics import PandaKinematics  # noqa: E402
from defgg_ros.sim.cell.sim_cell import ARM_DRIVES, CellSettings, SimCell  # noqa: E402
from defgg_ros.sim.scene_spec import load_scene  # noqa: E402

SCENE = ROOT / "sim_bringup" / "scenes" / "rigid_box.yaml"
FIRST_MOVE_S, STEP_S, SETTLE_S, AVERAGE_S, PERIOD_S = 2.0, 0.2, 0.6, 0.1, 0.001


FRANKA_P_NM_PER_RAD = np.array([p_gain for p_gain, _ in FRANKA_JTC_GAINS_PD])   # the controllers file's p


def controller_stiffness_z_n_per_mm(kin: PandaKinematics, q_rad, gains) -> float:
    """1 / (J K^-1 J^T)_zz at the TCP: the joint springs seen along z at the hand."""
    pin.computeJointJacobians(kin.model, kin.data, np.asarray(q_rad, dtype=float))
    pin.framesForwardKinematics(kin.model, kin.data, np.asarray(q_rad, dtype=float))
    jac = pin.getFrameJacobian(kin.model, kin.data, kin.tcp_id, pin.LOCAL_WORLD_ALIGNED)[:3]
    compliance = jac @ np.diag(1.0 / gains) @ jac.T
    return 1.0 / compliance[2, 2] / 1000.0


def held_force_z_n(cell) -> float:
    """The wrench's z force averaged over the last AVERAGE_S of a settle (the contact pushes the hand up: +z)."""
    cell.advance(SETTLE_S - AVERAGE_S)
    samples = []
    for _ in range(int(AVERAGE_S / PERIOD_S)):
        cell.advance(PERIOD_S)
        samples.append(float(cell.external_wrench()[0][2]))
    return float(np.mean(samples))


def main():
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--step-mm", type=float, default=0.5, help="how far each step lowers the command")
    parser.add_argument("--depth-mm", type=float, default=3.0, help="how far below the block's top to go")
    parser.add_argument("--arm-drive", choices=ARM_DRIVES, action="append",
                        help="the cell's arm drive (sim_cell.ARM_DRIVES; repeatable); default: each in turn")
    args = parser.parse_args()
    for drive in args.arm_drive or ARM_DRIVES:
        press(drive, args)


def press(drive: str, args):
    kin, gains = PandaKinematics(), FRANKA_P_NM_PER_RAD
    cell = SimCell(load_scene(SCENE), CellSettings(arm_drive=drive))
    try:
        q = cell.joint_state().positions[:7].copy()
        (bx, by, bz), _ = cell.object_poses()[0]
        top_z = bz + 0.025
        cell.gripper_move(0.0, 0.05)
        cell.advance(1.0)   # closed before it comes down
        heights_mm = np.arange(5.0, -args.depth_mm - 1e-9, -args.step_mm)
        print(f"# bench_hand_stiffness, arm_drive {drive}: closed fingers on the top of a rigid block (top at z "
              f"{top_z * 1e3:.1f} mm); command steps of {args.step_mm} mm, force averaged over "
              f"{AVERAGE_S * 1e3:.0f} ms when still")
        print("# fingertips' command above the top (mm) | force z (N) | fingertips measured above the top (mm) | "
              "franka JTC stiffness at this q (N/mm)")
        rows = []
        for height_mm in heights_mm:
            tcp_z = top_z + PANDA_FINGERTIP_BELOW_TCP_M + height_mm / 1000.0   # the fingertips' ends height_mm up
            solution, _ = kin.top_down_ik([bx, by, tcp_z], 0.3, q)
            move_s = STEP_S if rows else FIRST_MOVE_S
            cell.command_trajectory([(move_s, solution.q_rad, None, None)])
            cell.advance(move_s)
            force = held_force_z_n(cell)
            q = cell.joint_state().positions[:7].copy()
            measured_mm = (kin.fk(q)[2, 3] - PANDA_FINGERTIP_BELOW_TCP_M - top_z) * 1000.0
            franka = controller_stiffness_z_n_per_mm(kin, solution.q_rad, gains)
            rows.append((height_mm, force, measured_mm, franka))
            print(f"{height_mm:6.2f} {force:8.2f} {measured_mm:7.3f} {franka:7.2f}")
        pressed = [(h, f) for h, f, _, _ in rows if f > 1.0]
        if len(pressed) >= 2:
            slope = -np.polyfit([h for h, _ in pressed], [f for _, f in pressed], 1)[0]
            print(f"simulated arm ({drive}): {slope:.1f} N/mm along z past contact ({len(pressed)} steps pressing); "
                  f"franka_bringup's gains at the same pose: {np.median([r[3] for r in rows]):.2f} N/mm")
        else:
            print("fewer than two pressing steps: no slope")
    finally:
        cell.close()


if __name__ == "__main__":
    main()
