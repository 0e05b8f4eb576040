"""One of the demo's picks in one process, without ROS: the demo's place rule, the executor's sequence and
the simulated cell (defgg_ros.bringup.cell_sequence). Deterministic, so a pick that misbehaved can be replayed
(bench/bench_release_in_bin.py) and pinned by a test.
"""
from dataclasses import asdict, dataclass

import numpy as np

from defgg_ros.bringup.cell_sequence import PERIOD_S, CellSequenceDriver
from defgg_ros.bringup.demo_geometry import bin_place_xy, in_bin, release_tcp_z
from defgg_ros.control.kinematics import PandaKinematics
from defgg_ros.control.pick_place import PickPlaceSequence
from defgg_ros.control.sequence_types import GraspTarget, PlaceTarget
from defgg_ros.sim.cell.sim_cell import SimCell
from defgg_ros.sim.scene_spec import SceneSpec

MAX_SEQUENCE_SIM_S = 60.0


@dataclass
class PlacedObject:
    success: bool                 # the sequence's outcome
    failure_reason: str
    final_m: np.ndarray           # the object's centroid after the settle
    in_bin: bool
    lowest_z_m: float             # lowest centroid height seen
    fastest_after_release_mps: float


def closing_width_m(spec) -> float:
    """The object's extent along the fingers' closing direction at its own yaw (the grasp's yaw is the closing
    direction): a box's x side, a cylinder's diameter."""
    return float(spec.size_m[0])


def pick_into_bin(scene: SceneSpec, name: str, sequence_config, slot: int, offset_xy_m=(0.0, 0.0),
                  yaw_offset_rad: float = 0.0, finger_force_n: float = 0.0, release_max_z_m: float = 0.12,
                  settle_s: float = 4.0) -> PlacedObject:
    """Grasp the object at its top centre (moved by offset_xy_m, turned by yaw_offset_rad from its yaw,
    closing across its x side), place it as the demo does in the bin's slot-th quadrant, then settle_s more."""
    index = [o.name for o in scene.objects].index(name)
    spec = scene.objects[index]
    cell = SimCell(scene)
    try:
        start, _ = cell.object_poses()[index]
        grasp = GraspTarget((start[0] + offset_xy_m[0], start[1] + offset_xy_m[1], spec.height_m),
                            spec.yaw_rad + yaw_offset_rad, closing_width_m(spec), spec.youngs_modulus_pa,
                            finger_force_n)
        bins = asdict(scene.bin)       # as the demo reads it from the /fake_panda/scene topic (to_json_dict)
        x, y = bin_place_xy(bins, slot)
        place = PlaceTarget((x, y, release_tcp_z(spec.height_m, bins, release_max_z_m)), None)
        sequence = PickPlaceSequence(PandaKinematics(), sequence_config, grasp, place)
        track = []     # (sim time, centroid) after every period
        outcome = CellSequenceDriver(cell, sequence).run(
            MAX_SEQUENCE_SIM_S, on_period=lambda c: track.append((c.time_s, c.object_poses()[index][0])))
        released_s = cell.time_s - 2.0     # the sequence ends ~1-2 s after the fingers open
        for _ in range(int(round(settle_s / PERIOD_S))):
            cell.advance(PERIOD_S)
            track.append((cell.time_s, cell.object_poses()[index][0]))
        times = np.array([t for t, _ in track])
        centroids = np.array([c for _, c in track])
        speeds = np.linalg.norm(np.diff(centroids, axis=0), axis=1) / np.diff(times)
        return PlacedObject(outcome.success, outcome.failure_reason, centroids[-1], in_bin(centroids[-1], bins),
                            float(centroids[:, 2].min()), float(speeds[times[1:] >= released_s].max()))
    finally:
        cell.close()
