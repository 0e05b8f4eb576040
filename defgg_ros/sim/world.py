"""The grasp trials' world: a deformable world of the physics core (physics.py) with a table."""
from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass

import pybullet as p

from defgg_ros.sim import physics
from defgg_ros.sim.physics import GRAVITY_MPS2, time_step_for  # noqa: F401 - the trials' names for them

TABLE_SIZE_M = (1.0, 1.0, 0.04)
TABLE_RGBA = (0.6, 0.5, 0.4, 1)


@dataclass
class World:
    client: int
    table_id: int
    time_step_s: float
    table_top_z_m: float = 0.0
    # Called with the step length before every physics step (a pressing hand's drive: hand.Hand.drive).
    before_step: Callable[[float], None] | None = None

    def step(self, n: int = 1) -> None:
        for _ in range(n):
            if self.before_step is not None:
                self.before_step(self.time_step_s)
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


def connect(gui: bool = False) -> int:
    """A new physics server (DIRECT by default: no window, safe in workers)."""
    return p.connect(p.GUI if gui else p.DIRECT)


def create_world(client: int, youngs_moduli_pa=(), time_step_s: float | None = None) -> World:
    """Reset `client` to a deformable world with a table whose top is at z = 0.

    The time step is the stable one for the given moduli unless given.
    """
    dt = time_step_s if time_step_s is not None else time_step_for(youngs_moduli_pa)
    physics.reset_world(client, deformable=True, time_step_s=dt)
    half = [s / 2 for s in TABLE_SIZE_M]
    table = physics.static_box(client, half, [0, 0, -half[2]], TABLE_RGBA)
    return World(client, table, dt)
