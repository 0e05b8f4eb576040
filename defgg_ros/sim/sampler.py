"""Antipodal top-down grasp candidates with a hand/table collision filter.

Sampling: surface points with a near-horizontal normal; a horizontal ray
from each through the object finds the exit point; the pair is antipodal
when both normals lie within 36 deg of the closing axis (inside the
friction cone of mu = 0.8, 38.7 deg). Filter: the Panda
hand's boxes (hand.hand_boxes, opened wider by OPENING_CLEARANCE_M) at the
grasp and along the vertical approach must not touch the object or the
table. The collision check is PyBullet's own (static concave triangle mesh
vs boxes), so it judges the same geometry the trial simulates.

Second stage (sample_grasps(fill_short=True), the generator's since sampler 4): an object left with fewer
candidates than asked for gets more, appended after the first stage's (which stay as they were): the
refused pairs again at the opening that clears the object under the fingers' whole descent
(swept_opening_m; tapered shapes widen below the TCP), then pairs whose closing axis is turned within the
antipodal cone (a triangular prism has no pair along a face normal). docs/dataset.md, "Candidates".
"""
from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
import pybullet as p

from defgg_ros.constants import (
    FINGER_DEPTH_M,
    FINGER_PAD_WIDTH_M,
    GRASP_CANDIDATES_PER_OBJECT,
    GRASP_HEIGHT_RULES,
    GRIPPER_MAX_WIDTH_M,
    PANDA_FINGERTIP_BELOW_TCP_M,
    PREGRASP_HEIGHT_M,
    TABLE_CLEARANCE_M,
)
from defgg_ros.grasping.geometry import tcp_height_m
from defgg_ros.grasping.rectangles import GraspRect
from defgg_ros.sim import hand as hand_mod
from defgg_ros.sim.camera import TopDownCamera
from defgg_ros.sim.trial import OPENING_CLEARANCE_M, WorldGrasp
from defgg_ros.sim.trimesh_import import trimesh

# Bump when the sampling or the grasp height rule changes (invalidates cached candidates).
SAMPLER_VERSION = 4     # 4: the second stage (fill_short) and the palm's floor in tcp_height_m (tall objects)
ANTIPODAL_CONE_RAD = math.radians(36.0)   # friction cone of mu = 0.8 is 38.7 deg; 30 rejected every cone grasp
MAX_NORMAL_TILT_RAD = math.radians(50.0)   # contact normal vs horizontal
MIN_WIDTH_M = 0.005
COLLISION_TOLERANCE_M = 0.0005
APPROACH_STEP_M = 0.01
MAX_SAMPLE_ROUNDS = 20
SWEEP_CLEARANCE_M = 0.003      # a side, beyond the object's widest reach under the fingers (swept_opening_m)
SWEEP_STEP_M = 0.001           # height step of swept_opening_m's rays
SWEEP_RAYS_ACROSS = 5          # rays across the pad's width per height
SECOND_STAGE_SEED = 1          # the second stage's own stream: the first stage's draws stay as they were


@dataclass(frozen=True)
class Candidate:
    grasp: WorldGrasp          # in the object frame (object at the origin, yaw 0)
    contacts_m: tuple          # the two contact points


def _ray_hits(origin, direction, tris):
    """Distances t > 0 and face indices where the ray crosses triangles (Moller-Trumbore, vectorised)."""
    v0, v1, v2 = tris[:, 0], tris[:, 1], tris[:, 2]
    e1, e2 = v1 - v0, v2 - v0
    h = np.cross(direction, e2)
    a = np.einsum("ij,ij->i", e1, h)
    ok = np.abs(a) > 1e-12
    f = np.where(ok, 1.0 / np.where(ok, a, 1.0), 0.0)
    s = origin - v0
    u = f * np.einsum("ij,ij->i", s, h)
    q = np.cross(s, e1)
    v = f * (q @ direction)
    t = f * np.einsum("ij,ij->i", e2, q)
    hit = ok & (u >= 0) & (v >= 0) & (u + v <= 1) & (t > 1e-6)
    idx = np.nonzero(hit)[0]
    order = np.argsort(t[idx])
    return t[idx][order], idx[order]


# Where a candidate's TCP goes: "contacts" = at the sampled contacts' height (grasp_height_m; the
# datasets up to fem_v3), "executor" = at the height the executor derives from the depth image
# (grasping.geometry.tcp_height_m), with the contacts found again on that horizontal line. An
# image-space grasp has no height, so only "executor" labels the grasp that is later performed.
# The rule names are constants.GRASP_HEIGHT_RULES (the CLIs offer them without importing the sampler).


def check_height_rule(rule: str) -> str:
    if rule not in GRASP_HEIGHT_RULES:
        raise ValueError(f"grasp height rule must be one of {GRASP_HEIGHT_RULES}, got {rule!r}")
    return rule


def antipodal_pairs(mesh: trimesh.Trimesh, n_points: int, rng, height_rule: str = "contacts",
                    max_axis_turn_rad: float = 0.0) -> list:
    """Up to n_points antipodal candidates on a closed surface (object frame). The closing axis runs along
    the first contact's horizontal normal, turned about the vertical by a uniform angle up to
    max_axis_turn_rad (0: no turn and no draw, the first stage's stream)."""
    check_height_rule(height_rule)
    points, faces = trimesh.sample.sample_surface(mesh, n_points, seed=int(rng.integers(2**31)))
    normals = mesh.face_normals[faces]
    tris = mesh.triangles
    out = []
    for p1, n1 in zip(points, normals):
        horiz = np.array([n1[0], n1[1], 0.0])
        if np.linalg.norm(horiz) < math.cos(MAX_NORMAL_TILT_RAD):
            continue
        axis = -horiz / np.linalg.norm(horiz)          # into the object, horizontal
        if max_axis_turn_rad:
            axis = _turned_about_z(axis, rng.uniform(-max_axis_turn_rad, max_axis_turn_rad))
        t, idx = _ray_hits(p1 + axis * 1e-5, axis, tris)
        exits = [(ti, fi) for ti, fi in zip(t, idx) if mesh.face_normals[fi] @ axis > 0]
        if not exits:
            continue
        t2, f2 = exits[0]
        n2 = mesh.face_normals[f2]
        if math.acos(np.clip(n2 @ axis, -1, 1)) > ANTIPODAL_CONE_RAD:
            continue
        if math.acos(np.clip(-n1 @ axis, -1, 1)) > ANTIPODAL_CONE_RAD:
            continue
        if not MIN_WIDTH_M <= t2 <= GRIPPER_MAX_WIDTH_M - OPENING_CLEARANCE_M / 2:
            continue
        p2 = p1 + axis * t2
        centre = (p1 + p2) / 2
        if height_rule == "executor":
            found = pair_at_executor_height(centre, axis, mesh)
            if found is None:
                continue
            p1, p2, t2 = found
            centre = (p1 + p2) / 2
            z = centre[2]
        else:
            z = grasp_height_m(centre, _surface_height_m(centre, tris))
        yaw = math.atan2(axis[1], axis[0])
        out.append(Candidate(WorldGrasp((float(centre[0]), float(centre[1]), float(z)), yaw, float(t2)),
                             (tuple(p1), tuple(p2))))
    return out


def _turned_about_z(vector, angle_rad: float) -> np.ndarray:
    c, s = math.cos(angle_rad), math.sin(angle_rad)
    return np.array([c * vector[0] - s * vector[1], s * vector[0] + c * vector[1], vector[2]])


def pair_at_executor_height(centre, axis, mesh: trimesh.Trimesh):
    """The contacts on the horizontal line along `axis` through `centre`'s (x, y) at the executor's
    TCP height there: (p1, p2, width) if the line starts inside the object and leaves it through two
    faces within the antipodal cone and the hand's width range, else None."""
    tris = mesh.triangles
    for _ in range(2):      # the midpoint moves a little: take the height under the new one
        z = tcp_height_m(_surface_height_m(centre, tris))
        origin = np.array([centre[0], centre[1], z])
        ends = []
        for direction in (-axis, axis):
            t, idx = _ray_hits(origin, direction, tris)
            # The first face must be an exit (outward normal along the ray): the line starts inside.
            if not len(t) or math.acos(np.clip(mesh.face_normals[idx[0]] @ direction, -1, 1)) > ANTIPODAL_CONE_RAD:
                return None
            ends.append(origin + direction * t[0])
        centre = (ends[0] + ends[1]) / 2
    width = float(np.linalg.norm(ends[1] - ends[0]))
    if not MIN_WIDTH_M <= width <= GRIPPER_MAX_WIDTH_M - OPENING_CLEARANCE_M / 2:
        return None
    return ends[0], ends[1], width


def grasp_height_m(contact_centre_m, surface_top_z_m: float) -> float:
    """TCP height of a top-down grasp: at the contacts, but with the whole pad below the object's top.

    A pad reaching above the top edge touched only a few nodes of a coarse soft mesh, and at
    E = 2e4 Pa such grasps slipped out while lifting (measured on box_flat). So the TCP goes no higher
    than the surface under the grasp centre minus half a pad, and never so low that the fingertips
    would touch the table.
    """
    z = min(float(contact_centre_m[2]), surface_top_z_m - FINGER_DEPTH_M / 2)
    return max(z, PANDA_FINGERTIP_BELOW_TCP_M + TABLE_CLEARANCE_M)


def _surface_height_m(centre, tris) -> float:
    """Height of the object's top surface above (x, y) of `centre` (a downward ray)."""
    origin = np.array([centre[0], centre[1], 10.0])
    t, _ = _ray_hits(origin, np.array([0.0, 0.0, -1.0]), tris)
    return float(origin[2] - t[0]) if len(t) else float(centre[2])


class CollisionChecker:
    """The hand's boxes vs one object's surface and the table, in a private DIRECT server."""

    def __init__(self, surface: trimesh.Trimesh):
        self.client = p.connect(p.DIRECT)
        c = self.client
        col = p.createCollisionShape(p.GEOM_MESH, vertices=surface.vertices.tolist(),
                                     indices=surface.faces.ravel().tolist(), flags=p.GEOM_FORCE_CONCAVE_TRIMESH,
                                     physicsClientId=c)
        self.object_id = p.createMultiBody(0, col, physicsClientId=c)
        table = p.createCollisionShape(p.GEOM_BOX, halfExtents=[0.5, 0.5, 0.02], physicsClientId=c)
        self.table_id = p.createMultiBody(0, table, basePosition=[0, 0, -0.02], physicsClientId=c)
        self.box_ids = []
        for _, half in hand_mod.hand_boxes(0.0):
            shape = p.createCollisionShape(p.GEOM_BOX, halfExtents=half, physicsClientId=c)
            self.box_ids.append(p.createMultiBody(0, shape, physicsClientId=c))
        self.top_z_m = float(surface.vertices[:, 2].max())

    def close(self):
        p.disconnect(self.client)

    def hand_collides(self, grasp: WorldGrasp) -> bool:
        opening = grasp.finger_opening_m()
        lift = np.arange(0.0, max(0.0, self.top_z_m + PREGRASP_HEIGHT_M - grasp.position_m[2]) + 1e-9,
                         APPROACH_STEP_M)
        for dz in lift:  # at the grasp and along the top-down approach
            pose = hand_mod.world_T_hand(np.add(grasp.position_m, [0, 0, dz]), grasp.yaw_rad)
            if self._boxes_collide(pose, opening):
                return True
        return False

    def _boxes_collide(self, world_T_tcp, opening_m) -> bool:
        c = self.client
        quat = p.getQuaternionFromEuler([0, 0, math.atan2(world_T_tcp[1, 0], world_T_tcp[0, 0])])
        for body, (centre, _) in zip(self.box_ids, hand_mod.hand_boxes(opening_m)):
            pos = world_T_tcp[:3, :3] @ centre + world_T_tcp[:3, 3]
            p.resetBasePositionAndOrientation(body, pos.tolist(), quat, physicsClientId=c)
            for other in (self.object_id, self.table_id):
                if p.getClosestPoints(body, other, COLLISION_TOLERANCE_M, physicsClientId=c):
                    return True
        return False


def sample_grasps(surface: trimesh.Trimesh, seed: int, n_candidates: int = GRASP_CANDIDATES_PER_OBJECT,
                  keep: int | None = None, height_rule: str = "contacts", fill_short: bool = False) -> list:
    """~n_candidates antipodal candidates, collision-filtered; at most `keep`, in a seeded order. fill_short:
    fewer than `keep` (or n_candidates) free ones are topped up by the second stage (module docstring),
    appended, so the first stage's candidates keep their places."""
    rng = np.random.default_rng(seed)
    candidates = _sampled_pairs(surface, n_candidates, rng, height_rule)
    checker = CollisionChecker(surface)
    try:
        refused = [checker.hand_collides(c.grasp) for c in candidates]
        free = [c for c, hit in zip(candidates, refused) if not hit]
        order = rng.permutation(len(free))
        free = [free[i] for i in order]
        wanted = keep or n_candidates
        if fill_short and len(free) < wanted:
            again = [c for c, hit in zip(candidates, refused) if hit]
            free += second_stage(surface, checker, again, seed, n_candidates, height_rule)[:wanted - len(free)]
    finally:
        checker.close()
    return free[:keep] if keep else free


def _sampled_pairs(surface, n_candidates: int, rng, height_rule: str, max_axis_turn_rad: float = 0.0) -> list:
    """The first n_candidates antipodal pairs of up to MAX_SAMPLE_ROUNDS rounds of samples."""
    candidates = []
    for _ in range(MAX_SAMPLE_ROUNDS):
        candidates += antipodal_pairs(surface, 4 * n_candidates, rng, height_rule, max_axis_turn_rad)
        if len(candidates) >= n_candidates:
            break
    return candidates[:n_candidates]


def second_stage(surface, checker: CollisionChecker, refused: list, seed: int, n_candidates: int,
                 height_rule: str) -> list:
    """Collision-free candidates from the first stage's refused pairs at their swept opening, and from pairs
    with a turned closing axis (at the default opening when it clears, else the swept one); seeded order."""
    rng = np.random.default_rng([seed, SECOND_STAGE_SEED])
    turned = _sampled_pairs(surface, n_candidates, rng, height_rule, ANTIPODAL_CONE_RAD)
    found = [with_swept_opening(c, surface, checker) for c in refused]
    found += [c if not checker.hand_collides(c.grasp) else with_swept_opening(c, surface, checker) for c in turned]
    found = [c for c in found if c is not None]
    return [found[i] for i in rng.permutation(len(found))]


def with_swept_opening(candidate: Candidate, surface, checker: CollisionChecker) -> Candidate | None:
    """The candidate opened to swept_opening_m when that is wider than its own and the hand then clears object
    and table; None when it does not (or the opening exceeds the gripper's)."""
    grasp = candidate.grasp
    opening = swept_opening_m(grasp, surface)
    if opening <= grasp.finger_opening_m() or opening > GRIPPER_MAX_WIDTH_M:
        return None
    wider = WorldGrasp(grasp.position_m, grasp.yaw_rad, grasp.width_m, opening_m=float(opening))
    return None if checker.hand_collides(wider) else Candidate(wider, candidate.contacts_m)


def swept_opening_m(grasp: WorldGrasp, surface: trimesh.Trimesh) -> float:
    """The opening whose fingers clear the object over their whole descent: twice the object's farthest reach
    from the TCP along the closing axis, in the fingers' band (the pad's width across the axis) from the
    fingertips' height up, plus SWEEP_CLEARANCE_M a side. Rays from outside towards the TCP find the reach."""
    axis = np.array([math.cos(grasp.yaw_rad), math.sin(grasp.yaw_rad), 0.0])
    across = np.array([-axis[1], axis[0], 0.0])
    tcp = np.asarray(grasp.position_m, dtype=float)
    far_m = float(np.ptp(surface.bounds[:, :2], axis=0).max()) + 1.0     # outside the object
    heights = np.arange(tcp[2] - PANDA_FINGERTIP_BELOW_TCP_M, surface.bounds[1, 2] + 1e-9, SWEEP_STEP_M)
    offsets = np.linspace(-FINGER_PAD_WIDTH_M / 2, FINGER_PAD_WIDTH_M / 2, SWEEP_RAYS_ACROSS)
    tris = surface.triangles
    reach = 0.0
    for side in (axis, -axis):
        for z in heights:
            for offset in offsets:
                origin = np.array([tcp[0], tcp[1], z]) + side * far_m + across * offset
                t, _ = _ray_hits(origin, -side, tris)
                if len(t):
                    reach = max(reach, far_m - float(t[0]))
    return 2 * (reach + SWEEP_CLEARANCE_M)


def grasp_rect(grasp: WorldGrasp, camera: TopDownCamera | None = None) -> GraspRect:
    """Image rectangle of a world grasp: angle from u towards v in [-pi/2, pi/2], sizes in px."""
    camera = camera or TopDownCamera()
    uv = camera.world_to_pixel([grasp.position_m])[0]
    depth = camera.base_T_camera[2, 3] - grasp.position_m[2]
    # image v runs along -y, so a world yaw maps to angle -yaw in the image
    angle = -grasp.yaw_rad
    angle = (angle + math.pi / 2) % math.pi - math.pi / 2
    return GraspRect(float(uv[0]), float(uv[1]), float(angle), float(camera.metres_to_pixels(grasp.width_m, depth)),
                     float(camera.metres_to_pixels(FINGER_PAD_WIDTH_M, depth)))
