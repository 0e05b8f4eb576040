"""Depth (+ stiffness or per-object moduli) + camera pose -> feasible grasps in the robot frame (no rclpy).

The one entry the grasp service uses for the tabletop planner: the robot self-filter (when joint
positions are given), tabletop perception, the moduli (an image, or SetStiffness-style entries
assigned to the perceived objects), the network on the height map and the feasibility rules.

The camera pose is an argument (`base_T_camera`, 4x4): the node passes what TF says (or its
`base_T_camera` parameter as the fallback), so this module never needs to know where it came from.
"""
from __future__ import annotations

from dataclasses import dataclass, replace

import numpy as np

from defgg_ros.perception.self_filter import RobotSelfFilter
from defgg_ros.perception.stiffness_assignment import assign_stiffness
from defgg_ros.perception.tabletop import TabletopConfig, TabletopView
from defgg_ros.perception.tabletop import perceive as perceive_view
from defgg_ros.planning.tabletop_grasps import TabletopNetworkView, TabletopPlan, prepare_tabletop, search_tabletop


class NoFeasibleGrasp(ValueError):
    """Objects were found, but none can be grasped (reason in the message; per object in `rejected`: label ->
    which test rejected it, planning/tabletop_grasps.REJECTIONS)."""

    def __init__(self, message: str, rejected: dict | None = None):
        super().__init__(message)
        self.rejected = dict(rejected or {})


@dataclass(frozen=True)
class TabletopResult:
    view: TabletopView
    plan: TabletopPlan
    youngs_modulus_pa: np.ndarray    # HxW, what the planner used (0 = background)
    robot_mask: np.ndarray | None    # HxW bool, the self-filter's pixels (None: not applied)

    @property
    def grasps(self) -> list:
        return self.plan.grasps


def object_centroids_px(labels: np.ndarray, object_ids) -> dict:
    """label -> (u, v) pixel centroid of its image pixels (for ROI-addressed stiffness entries)."""
    out = {}
    for label in object_ids:
        vs, us = np.nonzero(labels == label)
        if vs.size:
            out[int(label)] = (float(us.mean()), float(vs.mean()))
    return out


@dataclass(frozen=True)
class PerceivedObjects:
    """TabletopPlanner.perceive's result: the view and the moduli of one frame, before the network."""
    view: TabletopView
    targets: set | None              # object labels to grasp (None = all)
    youngs_modulus_pa: np.ndarray    # HxW, what the planner uses (0 = background)
    robot_mask: np.ndarray | None    # HxW bool, the self-filter's pixels (None: not applied)


@dataclass(frozen=True)
class PreparedFrame:
    """TabletopPlanner.prepare's result: one frame perceived and through the network, not yet searched."""
    objects: PerceivedObjects        # its moduli as float32, as the result reports them
    network: TabletopNetworkView


class TabletopPlanner:
    def __init__(self, predictor, config: TabletopConfig | None = None, default_youngs_modulus_pa: float = 2e6,
                 self_filter: RobotSelfFilter | None = None):
        self.predictor = predictor
        self.config = config or TabletopConfig()
        self.default_youngs_modulus_pa = float(default_youngs_modulus_pa)
        self.self_filter = self_filter

    def plan(self, depth_m, camera_k, base_T_camera, top_k: int = 1, youngs_modulus_pa=None, entries=(),
             joint_positions: dict | None = None) -> TabletopResult:
        """Raises ValueError subclasses: TabletopError (no table, no object), NoFeasibleGrasp.
        The same as search(prepare(...), top_k)."""
        return self.search(self.prepare(depth_m, camera_k, base_T_camera, youngs_modulus_pa, entries,
                                        joint_positions), top_k)

    def prepare(self, depth_m, camera_k, base_T_camera, youngs_modulus_pa=None, entries=(),
                joint_positions: dict | None = None, checkpoint=None) -> PreparedFrame:
        """Everything of plan() that depends on the frame only, not on top_k: the self-filter, perception,
        the moduli, the network on the height map, the free space. Raises what plan() raises for a frame
        without table or objects. checkpoint: called between stages (perception/frame_worker.py).
        The same as network(perceive(...)): perception on arrival runs the two in separate threads."""
        return self.network(self.perceive(depth_m, camera_k, base_T_camera, youngs_modulus_pa, entries,
                                          joint_positions, checkpoint), checkpoint)

    def perceive(self, depth_m, camera_k, base_T_camera, youngs_modulus_pa=None, entries=(),
                 joint_positions: dict | None = None, checkpoint=None) -> PerceivedObjects:
        """prepare's first part: the self-filter, perception, the objects' moduli."""
        robot = None
        if self.self_filter is not None and joint_positions:
            robot = self.self_filter.mask(joint_positions, base_T_camera, camera_k, depth_m)
        view = perceive_view(depth_m, camera_k, base_T_camera, self.config, robot, checkpoint)
        if not view.object_ids:
            raise NoFeasibleGrasp("no object found above the table in the workspace box (blobs smaller than "
                                  f"{self.config.min_object_area_m2 * 1e4:.1f} cm^2 are ignored)")
        if youngs_modulus_pa is None:
            youngs_modulus_pa, _ = assign_stiffness(view.labels, object_centroids_px(view.labels, view.object_ids),
                                                    entries, self.default_youngs_modulus_pa)
        elif np.shape(youngs_modulus_pa) != view.depth_m.shape:
            raise ValueError(f"stiffness image {np.shape(youngs_modulus_pa)} does not match the depth's "
                             f"{view.depth_m.shape}")
        return PerceivedObjects(view, None, youngs_modulus_pa, robot)

    def network(self, objects: PerceivedObjects, checkpoint=None) -> PreparedFrame:
        """prepare's second part: the network on the height map, the free space."""
        if checkpoint is not None:
            checkpoint()
        network = prepare_tabletop(objects.view, self.predictor, objects.youngs_modulus_pa,
                                   self.default_youngs_modulus_pa, checkpoint)
        moduli = np.asarray(objects.youngs_modulus_pa, np.float32)
        return PreparedFrame(replace(objects, youngs_modulus_pa=moduli), network)

    def search(self, prepared: PreparedFrame, top_k: int = 1) -> TabletopResult:
        """The grasps of a prepared frame (any number of searches may share one PreparedFrame)."""
        objects = prepared.objects
        plan = search_tabletop(prepared.network, top_k, objects.targets)
        view = prepared.network.view
        if not plan.grasps:
            raise NoFeasibleGrasp(
                f"no feasible grasp on the {len(view.object_ids)} object(s) in the workspace; rejected by "
                f"({plan.rejection_summary() or 'no object searched'}): too low = nothing at the fingertips' level "
                "under the centre, width = wider than the gripper's opening minus clearance along every closing "
                "direction, collision = a finger would land on a neighbour or on space the camera cannot see, "
                "workspace = outside the workspace box, reach = beyond the arm's top-down reach", plan.rejected)
        return TabletopResult(view, plan, objects.youngs_modulus_pa, objects.robot_mask)
