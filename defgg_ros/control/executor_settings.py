"""The executor's parameters as the sequence's configuration (pure: a parameter dict in, SequenceConfig out).

defgg_ros/ros/params/executor_node.yaml names and bounds each parameter; the node reads them and calls these.
"""
import functools

import numpy as np

from defgg_ros.control.bin_slots import check_drop_xy, default_drop_xy
from defgg_ros.control.kinematics import PandaKinematics
from defgg_ros.control.sequence_types import SequenceConfig


def sequence_config(p: dict) -> SequenceConfig:
    """The sequence's configuration from the executor's parameters (ValueError: a combination it refuses)."""
    if len(p["place_position_m"]) != 3:
        raise ValueError(f"place_position_m must have 3 values, got {p['place_position_m']}")
    via = tuple(float(v) for v in p["transfer_via_position_m"]) if p["use_transfer_via"] else None
    config = SequenceConfig(
        table_z_m=float(p["table_z_m"]), limits_scale=float(p["limits_scale"]),
        pregrasp_height_m=float(p["pregrasp_height_m"]), descent_speed_mps=float(p["descent_speed_mps"]),
        grasp_depth_below_surface_m=float(p["grasp_depth_below_surface_m"]),
        grasp_height_rule=str(p["grasp_height_rule"]),
        line_speed_mps=float(p["line_speed_mps"]), lift_height_m=float(p["lift_height_m"]),
        place_approach_height_m=float(p["place_approach_height_m"]),
        contact_force_threshold_n=float(p["contact_force_threshold_n"]),
        watchdog_timeout_s=float(p["watchdog_timeout_s"]),
        arrival_joint_atol_rad=float(p["arrival_joint_atol_rad"]),
        settle_timeout_s=float(p["settle_timeout_s"]), gripper_timeout_s=float(p["gripper_timeout_s"]),
        slip_width_fraction=float(p["slip_width_fraction"]), sample_dt_s=float(p["trajectory_sample_dt_s"]),
        transfer_via_position_m=via, still_speed_radps=float(p["still_speed_radps"]),
        transfer_max_tcp_accel_mps2=float(p["transfer_max_tcp_accel_mps2"]) or None,
        rest_hold_s=float(p["rest_hold_s"]), stop_timeout_s=float(p["stop_timeout_s"]),
        observation_q_rad=tuple(float(v) for v in p["observation_q_rad"]) if p["recover_after_failure"] else None,
        observation_lift_m=float(p["observation_lift_m"]),
        observation_tolerance_rad=float(p["observation_tolerance_rad"]),
        place_lowering_speed_mps=float(p["place_lowering_speed_mps"]),
        place_release_clearance_m=float(p["place_release_clearance_m"]),
        place_release_opening_m=float(p["place_release_opening_m"]),
        recovery_drop_xy_m=recovery_drop_xy(p))
    config.validate()
    return config


def recovery_drop_xy(p: dict) -> tuple:
    """The recovery's put-down point (x, y): recovery_drop_xy_m, or at [0, 0] the point of workspace_box_m nearest
    the observation pose's TCP, away from the base (ValueError: outside the box or inside the keep-out)."""
    box, keep_out = p["workspace_box_m"], float(p["base_keep_out_radius_m"])
    if any(float(v) != 0.0 for v in p["recovery_drop_xy_m"]):
        return check_drop_xy(p["recovery_drop_xy_m"], box, keep_out)
    return default_drop_xy(_tcp_xy_m(tuple(float(v) for v in p["observation_q_rad"])), box, keep_out)


@functools.lru_cache(maxsize=4)
def _tcp_xy_m(q_rad: tuple) -> tuple:
    return tuple(float(v) for v in PandaKinematics().fk(np.asarray(q_rad))[:2, 3])
