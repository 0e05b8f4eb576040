"""Soft objects that sleep as static meshes until the hand comes near.

Why: a 130-node FEM box resting on the table costs ~9 ms per 0.5 ms step on
this machine (measured, bench/bench_fake_driver.py): the table contact alone
makes it as dear as a grasp. A cell with several soft objects would run at a
few percent of real time although nothing touches them. So a soft object is
*dormant* (a static triangle mesh of its current node positions: it looks and
collides the same) until the TCP comes within ACTIVATE_DISTANCE_M, then it is
an FEM body restored to exactly those node positions; once it is at rest,
away from the hand and untouched, it falls dormant again with its deformed
shape. Sleeping rigid bodies do the same in every physics engine.
"""
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import pybullet as p

from defgg_ros.sim import meshes
from defgg_ros.sim.cell import grid_mesh as cell_grid_mesh
from defgg_ros.sim.cell import objects as cell_objects
from defgg_ros.sim.scene_spec import SceneObject

ACTIVATE_DISTANCE_M = 0.06    # TCP to the object's bounding box
DEACTIVATE_DISTANCE_M = 0.08  # hysteresis; small enough that working on a neighbour 16 cm away lets it sleep
REST_MOTION_M = 5e-4          # max node travel between two checks to count as at rest
# Checks in a row that must find it at rest before it sleeps. One is not enough: a body let go by
# the fingers is at rest for an instant at the top of its fall, and slept there, frozen in mid-air
# (the demo's rubber block: released over the bin, stuck to a finger for a moment, found at 0.107 m
# above the table in 11 of 12 demo runs). Two checks 0.05 s apart see a fall from rest move 1.2 cm.
REST_CHECKS = 2


@dataclass
class SoftObject:
    spec: SceneObject
    tet: meshes.TetMesh
    nodes_m: np.ndarray           # world-frame nodes (kept current while active)
    body: int = -1
    active: bool = False
    proxy_count: int = 0
    rest_checks: int = 0          # consecutive activity checks that found it at rest


def _rotation_z(yaw_rad):
    c, s = np.cos(yaw_rad), np.sin(yaw_rad)
    return np.array([[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]])


def spawn_dormant(client: int, spec: SceneObject, scratch_dir: Path) -> SoftObject:
    """A soft object resting on the table at its scene pose, dormant."""
    if spec.shape == "box":
        tet = cell_grid_mesh.box_tet_mesh(spec.size_m, spec.fem_cell_size_m, scratch_dir)
    else:
        tet = cell_objects.cell_tet_mesh(spec)
    lowest = tet.nodes_m[:, 2].min()
    offset = np.array([spec.position_xy_m[0], spec.position_xy_m[1], -lowest])
    obj = SoftObject(spec, tet, tet.nodes_m @ _rotation_z(spec.yaw_rad).T + offset)
    _make_proxy(client, obj, scratch_dir)
    return obj


def _make_proxy(client, obj: SoftObject, scratch_dir: Path):
    # PyBullet caches meshes by file name: every proxy gets a new file.
    obj.proxy_count += 1
    path = Path(scratch_dir) / f"{obj.spec.name}_{obj.proxy_count}.obj"
    meshes.write_obj(path, obj.nodes_m, obj.tet.surface_faces)
    col = p.createCollisionShape(p.GEOM_MESH, fileName=str(path), flags=p.GEOM_FORCE_CONCAVE_TRIMESH,
                                 physicsClientId=client)
    vis = p.createVisualShape(p.GEOM_MESH, fileName=str(path), physicsClientId=client)
    obj.body = p.createMultiBody(0, col, vis, physicsClientId=client)
    p.changeDynamics(obj.body, -1, lateralFriction=cell_objects.MATERIAL.object_friction, physicsClientId=client)
    obj.active = False


def activate(client: int, obj: SoftObject) -> None:
    """Replace the static proxy by the FEM body with the same node positions."""
    p.removeBody(obj.body, physicsClientId=client)
    # Lift by the contact margin so the restored nodes do not start inside the table.
    nodes = obj.nodes_m + [0.0, 0.0, cell_objects.SOFT_COLLISION_MARGIN_M]
    obj.body = cell_objects.load_soft_body(client, obj.spec, obj.tet, [0, 0, 0], [0, 0, 0, 1])
    p.resetMeshData(obj.body, vertices=nodes.tolist(), physicsClientId=client)
    p.resetBaseVelocity(obj.body, [0, 0, 0], [0, 0, 0], physicsClientId=client)
    obj.nodes_m = nodes
    obj.active = True
    obj.rest_checks = 0


def deactivate(client: int, obj: SoftObject, scratch_dir: Path) -> None:
    """Freeze the FEM body into a static proxy of its current (deformed) shape."""
    obj.nodes_m = cell_objects.soft_nodes_m(client, obj.body)
    p.removeBody(obj.body, physicsClientId=client)
    _make_proxy(client, obj, scratch_dir)


def distance_to_box_m(point, nodes_m) -> float:
    """Distance from a point to the axis-aligned bounding box of the nodes (0 inside)."""
    lo, hi = nodes_m.min(axis=0), nodes_m.max(axis=0)
    return float(np.linalg.norm(np.maximum(0.0, np.maximum(lo - point, point - hi))))


def touches_robot(client: int, obj: SoftObject, robot: int) -> bool:
    return bool(p.getContactPoints(bodyA=obj.body, bodyB=robot, physicsClientId=client))


def update_activity(client: int, objects: list, robot: int, tcp_m, scratch_dir: Path) -> bool:
    """Wake soft objects near the TCP and put resting, untouched ones to sleep.

    Returns True when any object changed state (the time step may change).
    """
    changed = False
    for obj in objects:
        if not obj.active:
            if distance_to_box_m(tcp_m, obj.nodes_m) < ACTIVATE_DISTANCE_M:
                activate(client, obj)
                changed = True
            continue
        nodes = cell_objects.soft_nodes_m(client, obj.body)
        still = np.abs(nodes - obj.nodes_m).max() < REST_MOTION_M
        obj.nodes_m = nodes
        obj.rest_checks = obj.rest_checks + 1 if still else 0
        at_rest = obj.rest_checks >= REST_CHECKS
        if at_rest and distance_to_box_m(tcp_m, nodes) > DEACTIVATE_DISTANCE_M and not touches_robot(
                client, obj, robot):
            deactivate(client, obj, scratch_dir)
            changed = True
    return changed
