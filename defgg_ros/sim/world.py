"""A deformable PyBullet world with the settings that were stable on this machine.

Measured in ../shared/notes/pybullet-fem-facts.md: the default 1/240 s step
blew up with gripper contact at every E; 5e-4 s was stable at 2e4 and 2e5
Pa, 2.5e-4 s at 2e6 Pa; rigid bodies (E > MAX_SOFT_BODY_YOUNGS_MODULUS_PA)
were fine at any step. Gravity is zero after a deformable reset, so it is
set afterwards.
"""
from __future__ import annotations

from dataclasses import dataclass

import pybullet as p

from defgg_ros.constants import MAX_SOFT_BODY_YOUNGS_MODULUS_PA
from defgg_ros.stiffness import check_youngs_modulus

GRAVITY_MPS2 = 9.81
SPARSE_SDF_VOXEL_SIZE_M = 0.01
# (upper E bound in Pa, time step in s); first match wins.
TIME_STEPS_S = ((2e5, 5e-4), (MAX_SOFT_BODY_YOUNGS_MODULUS_PA, 2.5e-4))
RIGID_TIME_STEP_S = 1e-3
TABLE_SIZE_M = (1.0, 1.0, 0.04)
TABLE_FRICTION = 0.8


@dataclass
class World:
    client: int
    table_id: int
    time_step_s: float
    table_top_z_m: float = 0.0

    def step(self, n: int = 1) -> None:
        for _ in range(n):
            p.stepSimulation(physicsClientId=self.client)

    def set_gravity(self, gravity_mps2) -> None:
        p.setGravity(*gravity_mps2, physicsClientId=self.client)

    def gravity(self) -> list:
        """The engine's gravity now (m/s^2), read back from it."""
        params = p.getPhysicsEngineParameters(physicsClientId=self.client)
        return [params.get(f"gravityAcceleration{a}", float("nan")) for a in "XYZ"]

    def move_table(self, top_z_m: float) -> None:
        """Move the table so its top is at top_z_m (the defgraspsim pickup takes it out of the way)."""
        half_z = TABLE_SIZE_M[2] / 2
        p.resetBasePositionAndOrientation(self.table_id, [0, 0, top_z_m - half_z], [0, 0, 0, 1],
                                          physicsClientId=self.client)


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


def connect(gui: bool = False) -> int:
    """A new physics server (DIRECT by default: no window, safe in workers)."""
    return p.connect(p.GUI if gui else p.DIRECT)


def create_world(client: int, youngs_moduli_pa=(), time_step_s: float | None = None) -> World:
    """Reset `client` to a deformable world with a table whose top is at z = 0.

    The time step is the stable one for the given moduli unless given.
    """
    dt = time_step_s if time_step_s is not None else time_step_for(youngs_moduli_pa)
    p.resetSimulation(p.RESET_USE_DEFORMABLE_WORLD, physicsClientId=client)
    p.setGravity(0, 0, -GRAVITY_MPS2, physicsClientId=client)
    p.setTimeStep(dt, physicsClientId=client)
    p.setPhysicsEngineParameter(sparseSdfVoxelSize=SPARSE_SDF_VOXEL_SIZE_M, physicsClientId=client)
    half = [s / 2 for s in TABLE_SIZE_M]
    col = p.createCollisionShape(p.GEOM_BOX, halfExtents=half, physicsClientId=client)
    vis = p.createVisualShape(p.GEOM_BOX, halfExtents=half, rgbaColor=[0.6, 0.5, 0.4, 1], physicsClientId=client)
    table = p.createMultiBody(0, col, vis, basePosition=[0, 0, -half[2]], physicsClientId=client)
    p.changeDynamics(table, -1, lateralFriction=TABLE_FRICTION, physicsClientId=client)
    return World(client, table, dt)
