"""The physics core: every PyBullet setting that decides how a body behaves, in one place.

Both clients go through here: the grasp trials that label the data (world.py, objects.py, hand.py,
trial.py) and the simulated cell that the demo runs (cell.py, cell_objects.py, cell_soft.py). So the
physics that labels the data cannot drift from the physics of the cell, and the cell's objects are made of the
material of the protocol that labelled the shipped weights (cell_objects.MATERIAL).

Facts behind the numbers (docs/dataset.md, "PyBullet FEM"): the default 1/240 s step blew up with
gripper contact at every E; 5e-4 s was stable at 2e4 and 2e5 Pa, 2.5e-4 s at 2e6 Pa; Neo-Hookean
damping 0 exploded even in a drop test; E >= 2e7 Pa as a soft body was flung, so stiffer parts are
rigid bodies. Gravity is zero after a deformable reset, so it is set afterwards. Bullet multiplies
the friction coefficients of the two bodies in a contact (rigid-rigid and soft-rigid alike).
"""
from __future__ import annotations

import numpy as np
import pybullet as p

from defgg_ros.constants import GRAVITY_MPS2, MAX_SOFT_BODY_YOUNGS_MODULUS_PA, POISSON_RATIO
from defgg_ros.sim.material import DEFAULT_FRICTION, MATERIALS, Material  # noqa: F401 - the core's material table
from defgg_ros.stiffness import check_youngs_modulus

SPARSE_SDF_VOXEL_SIZE_M = 0.01
# (upper E bound in Pa, time step in s); first match wins.
TIME_STEPS_S = ((2e5, 5e-4), (MAX_SOFT_BODY_YOUNGS_MODULUS_PA, 2.5e-4))
RIGID_TIME_STEP_S = 1e-3
NEO_HOOKEAN_DAMPING = 0.01
SOFT_COLLISION_MARGIN_M = 0.002


class SoftBodyError(RuntimeError):
    """PyBullet refused or broke a soft body."""


def time_step_for(youngs_moduli_pa) -> float:
    """Largest stable step for a world holding objects of these moduli (Pa)."""
    step = RIGID_TIME_STEP_S
    for e in youngs_moduli_pa:
        e = check_youngs_modulus(e)
        for bound, dt in TIME_STEPS_S:
            if e <= bound:
                step = min(step, dt)
                break
    return step


def reset_world(client: int, deformable: bool, time_step_s: float) -> None:
    """An empty world with gravity on: deformable (FEM) or rigid-only."""
    if deformable:
        p.resetSimulation(p.RESET_USE_DEFORMABLE_WORLD, physicsClientId=client)
        p.setPhysicsEngineParameter(sparseSdfVoxelSize=SPARSE_SDF_VOXEL_SIZE_M, physicsClientId=client)
    else:
        p.resetSimulation(physicsClientId=client)
    p.setGravity(0, 0, -GRAVITY_MPS2, physicsClientId=client)     # zero after a reset
    p.setTimeStep(time_step_s, physicsClientId=client)


def neo_hookean_lame(youngs_modulus_pa: float, poisson_ratio: float) -> tuple:
    """(mu, lambda) in Pa of a Neo-Hookean solid with this E and nu."""
    mu = youngs_modulus_pa / (2 * (1 + poisson_ratio))
    lam = youngs_modulus_pa * poisson_ratio / ((1 + poisson_ratio) * (1 - 2 * poisson_ratio))
    return mu, lam


def soft_body_parameters(youngs_modulus_pa: float, poisson_ratio: float | None, mass_kg: float,
                         friction: float = DEFAULT_FRICTION) -> dict:
    """The loadSoftBody arguments of one FEM body (everything but its file and pose)."""
    nu = POISSON_RATIO if poisson_ratio is None else poisson_ratio
    mu, lam = neo_hookean_lame(youngs_modulus_pa, nu)
    return {"mass": mass_kg, "useNeoHookean": 1, "NeoHookeanMu": mu, "NeoHookeanLambda": lam,
            "NeoHookeanDamping": NEO_HOOKEAN_DAMPING, "collisionMargin": SOFT_COLLISION_MARGIN_M,
            "frictionCoeff": friction, "useFaceContact": 1, "useSelfCollision": 0}


# (client, body) -> the parameters it was loaded with, so a test can compare two clients' bodies.
_LOADED: dict = {}


def load_soft_body(client: int, vtk_path, position, orientation, parameters: dict) -> int:
    """One FEM body from a tet mesh file with soft_body_parameters(...)."""
    body = p.loadSoftBody(str(vtk_path), basePosition=list(position), baseOrientation=list(orientation),
                          scale=1.0, physicsClientId=client, **parameters)
    if body < 0:
        raise SoftBodyError(f"PyBullet could not load the soft body {vtk_path}")
    _LOADED[(client, body)] = dict(parameters)
    return body


def loaded_parameters(client: int, body: int) -> dict:
    """The parameters load_soft_body gave this body."""
    return dict(_LOADED[(client, body)])


def set_friction(client: int, body: int, links, friction: float, **extra) -> None:
    """A rigid body's own friction coefficient on these links (-1 = base)."""
    for link in links:
        p.changeDynamics(body, link, lateralFriction=friction, physicsClientId=client, **extra)


# A rigid object of the simulated cell rests on the table for a whole session: without rolling and spinning
# friction a cylinder rolled and a box crept about. The trials' rigid objects never had them (every dataset's
# labels were made without), so they keep none: the one named difference between the two.
CELL_ROLLING_FRICTION = 1e-4
CELL_SPINNING_FRICTION = 1e-3


def set_rigid_object_friction(client: int, body: int, links, material: Material, resting: bool = False) -> None:
    """A rigid object's friction: the material's object coefficient on these links (-1 = base); resting (the
    cell's objects) adds CELL_ROLLING_FRICTION and CELL_SPINNING_FRICTION."""
    extra = {"rollingFriction": CELL_ROLLING_FRICTION, "spinningFriction": CELL_SPINNING_FRICTION} if resting else {}
    set_friction(client, body, links, material.object_friction, **extra)


def couple_fingers(client: int, body: int, finger_a: int, finger_b: int, max_force_n: float, erp: float) -> int:
    """Keep two prismatic fingers of `body` symmetric (q_a = q_b): PyBullet ignores the URDF <mimic>,
    and without the coupling fingers and object slid sideways together and scores halved. Returns the
    constraint id (removeConstraint frees them, e.g. to lock each finger on its own)."""
    gear = p.createConstraint(body, finger_a, body, finger_b, p.JOINT_GEAR, [1, 0, 0], [0, 0, 0], [0, 0, 0],
                              physicsClientId=client)
    p.changeConstraint(gear, gearRatio=-1, maxForce=max_force_n, erp=erp, physicsClientId=client)
    return gear


def static_box(client: int, half_extents, position, rgba, friction: float = DEFAULT_FRICTION) -> int:
    """A fixed box (table, wall)."""
    col = p.createCollisionShape(p.GEOM_BOX, halfExtents=list(half_extents), physicsClientId=client)
    vis = p.createVisualShape(p.GEOM_BOX, halfExtents=list(half_extents), rgbaColor=list(rgba),
                              physicsClientId=client)
    body = p.createMultiBody(0, col, vis, basePosition=list(position), physicsClientId=client)
    set_friction(client, body, [-1], friction)
    return body


def depth_from_buffer_m(depth_buffer, near_m: float, far_m: float) -> np.ndarray:
    """OpenGL depth buffer values in [0, 1] -> metric z along the optical axis (float64)."""
    d = np.asarray(depth_buffer, dtype=np.float64)
    return far_m * near_m / (far_m - (far_m - near_m) * d)


def soft_nodes_m(client: int, body: int) -> np.ndarray:
    """World positions of a soft body's simulation nodes."""
    _, vertices = p.getMeshData(body, -1, flags=p.MESH_DATA_SIMULATION_MESH, physicsClientId=client)
    return np.asarray(vertices, dtype=np.float64)
