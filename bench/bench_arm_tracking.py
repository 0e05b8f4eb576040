"""How the simulated arm follows the executor's trajectories, and when the arm controller would call a goal done.

    .venv/bin/python bench/bench_arm_tracking.py

Two motions as the executor plans them (the shipped limits_scale, 0.4 of the Panda's limits; 20 ms samples sent
with positions, velocities and accelerations, so the controller interpolates quintics): a joint-space transfer from
the observation pose to above the bin (Ruckig) and a 10 cm straight descent at 0.03 m/s (plan_line); and a stop
(plan_stop) from the transfer's commanded state halfway, as a cancel's stop starts. Each runs on SimCell alone
(rigid_box.yaml, 1 ms steps), with each of the cell's arm drives (sim_cell.ARM_DRIVES). Printed: the largest joint
error (desired - measured) on the way, the error and speed at the last point's time, and how long after it every
joint is first below the controller's stopped_velocity_tolerance (0.01 rad/s: when joint_trajectory_controller
calls the goal a success, docs/franka_contract.md). Nothing is asserted.
"""
import argparse
import sys
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from defgg_ros.control.kinematics import PandaKinematics  # noqa: E402
from defgg_ros.control.trajectories import panda_limits, plan_joint_motion, plan_line, plan_stop  # noqa: E402
from defgg_ros.ros.parameters import defaults  # noqa: E402
from defgg_ros.sim.cell.sim_cell import ARM_DRIVES, CellSettings, SimCell  # noqa: E402
from defgg_ros.sim.scene_spec import load_scene  # noqa: E402

SCENE = ROOT / "sim_bringup" / "scenes" / "rigid_box.yaml"
STOPPED_RADPS, STEP_S, AFTER_S = 0.01, 0.001, 1.0


def send(cell, trajectory) -> None:
    cell.command_trajectory([(float(t), q, qd, qdd) for t, q, qd, qdd in
                             zip(trajectory.times_s, trajectory.q_rad, trajectory.qd_radps, trajectory.qdd_radps2)
                             if t > 0.0])


def run(cell, trajectory) -> dict:
    """Send the sampled trajectory, step through it and AFTER_S past its end; the tracking figures."""
    send(cell, trajectory)
    start_s, end_s = cell.time_s, cell.time_s + trajectory.duration_s
    worst, at_end, stopped_after_s = 0.0, None, None
    while cell.time_s < end_s + AFTER_S:
        cell.advance(STEP_S)
        joints = cell.joint_state()
        q_des, _ = cell.tracker.sample(cell.time_s)
        error = float(np.max(np.abs(q_des - joints.positions[:7])))
        speed = float(np.max(np.abs(joints.velocities[:7])))
        worst = max(worst, error)
        if at_end is None and cell.time_s >= end_s - 1e-9:
            at_end = (error, speed)
        if at_end is not None and stopped_after_s is None and speed < STOPPED_RADPS:
            stopped_after_s = cell.time_s - end_s
    return {"duration_s": end_s - start_s, "worst_mrad": worst * 1e3, "end_mrad": at_end[0] * 1e3,
            "end_radps": at_end[1], "stopped_after_ms": None if stopped_after_s is None else stopped_after_s * 1e3}


def above_bin_q(kin, cfg, seed_q):
    """Joint positions with the TCP 25 cm above the centre of the executor's bin (bin_inner_m), pointing down."""
    x_min, x_max, y_min, y_max = cfg["bin_inner_m"]
    solution, _ = kin.top_down_ik([(x_min + x_max) / 2, (y_min + y_max) / 2, 0.25], 0.0, seed_q)
    return solution.q_rad


def stop_halfway(cell, kin, limits, cfg) -> dict:
    """A transfer back to above the bin, stopped halfway with the stop planned from its commanded state there."""
    q0 = cell.joint_state().positions[:7].copy()
    transfer = plan_joint_motion(q0, above_bin_q(kin, cfg, q0), limits, dt_s=cfg["trajectory_sample_dt_s"])
    send(cell, transfer)
    cell.advance(transfer.duration_s / 2)
    return run(cell, plan_stop(*transfer.state_at(transfer.duration_s / 2), limits))


def main():
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--arm-drive", choices=ARM_DRIVES, action="append",
                        help="the cell's arm drive (sim_cell.ARM_DRIVES; repeatable); default: each in turn")
    for drive in parser.parse_args().arm_drive or ARM_DRIVES:
        print_drive(drive)


def print_drive(drive: str):
    cfg = defaults("executor_node")
    kin, limits = PandaKinematics(), panda_limits(cfg["limits_scale"])
    cell = SimCell(load_scene(SCENE), CellSettings(arm_drive=drive))
    try:
        q0 = cell.joint_state().positions[:7].copy()
        rows = [("transfer to above the bin", run(cell, plan_joint_motion(q0, above_bin_q(kin, cfg, q0), limits,
                                                                          dt_s=cfg["trajectory_sample_dt_s"])))]
        above_table, _ = kin.top_down_ik([0.5, -0.15, 0.15], 0.0, cell.joint_state().positions[:7])
        rows.append(("move above the table", run(cell, plan_joint_motion(cell.joint_state().positions[:7],
                                                                         above_table.q_rad, limits,
                                                                         dt_s=cfg["trajectory_sample_dt_s"]))))
        line = plan_line(kin, cell.joint_state().positions[:7], [0.0, 0.0, -0.10], limits, cfg["descent_speed_mps"],
                         cfg["trajectory_sample_dt_s"])
        rows.append(("10 cm descent at descent_speed_mps", run(cell, line)))
        rows.append(("stop halfway through a transfer", stop_halfway(cell, kin, limits, cfg)))
        print(f"# bench_arm_tracking, arm_drive {drive}: SimCell alone, 1 ms steps; errors desired - measured, max "
              "over joints")
        print("# motion | duration (s) | worst error on the way (mrad) | error at its end (mrad) | speed at its end "
              "(rad/s) | every joint < 0.01 rad/s after its end (ms)")
        for name, r in rows:
            stopped = "not within 1 s" if r["stopped_after_ms"] is None else f"{r['stopped_after_ms']:.0f}"
            print(f"{name:<36} {r['duration_s']:6.2f} {r['worst_mrad']:7.2f} {r['end_mrad']:7.2f} "
                  f"{r['end_radps']:7.4f} {stopped:>8}")
    finally:
        cell.close()


if __name__ == "__main__":
    main()
