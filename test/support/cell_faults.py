"""Faults put into a real simulated cell (defgg_ros.sim.cell.sim_cell.SimCell) by tests."""
import pybullet as p


def put_beyond_the_table_edge(cell, object_index: int = 0) -> None:
    """One scene object put 10 cm past the table's +x edge, 5 cm up: nothing is under it."""
    (sx, _, _), (cx, cy) = cell.scene.table_size_m, cell.scene.table_center_xy_m
    p.resetBasePositionAndOrientation(cell.object_ids[object_index], [cx + sx / 2 + 0.1, cy, 0.05], [0, 0, 0, 1],
                                      physicsClientId=cell.client)
