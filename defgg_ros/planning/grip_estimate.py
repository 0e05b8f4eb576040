"""The force a perceived object's grasp should close with: the rule its model's labels were made with.

Def-GG-CNN's quality is the probability that a grasp holds when closed with the force of its training labels
(the weights record the rule: grip_force.LabelGripRule). The legacy rule needs only Young's modulus, which
the executor knows from the Grasp. The defgraspsim rule (F = FOS * m * g / mu, split over the fingers) also
needs the object's mass: the trials took m = tet-mesh volume x OBJECT_DENSITY_KG_M3, so the cell takes the
volume under the object's cells of the top-down height map times the same density (or the node's
object_density_kg_m3 for a cell whose objects are not water-like).

What the volume can and cannot see: each height-map cell counts as solid down to the table, so overhangs,
hollows and handles count as full (a mug's or a bowl's mass comes out high: more squeeze, not less), and
what the camera cannot see (the far side of a tall object, parts hidden by a neighbour) is missed (mass low).
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from defgg_ros.constants import OBJECT_DENSITY_KG_M3
from defgg_ros.grip_force import LabelGripRule
from defgg_ros.perception.tabletop import CELL_M


@dataclass(frozen=True)
class GripEstimate:
    mass_kg: float               # volume under the object's height-map cells x density
    softest_modulus_pa: float    # the labels' force used the object's softest part
    finger_force_n: float        # the labels' force per finger; 0 = the executor's own (legacy) rule


def object_volume_m3(grid_height_m, grid_labels, label: int, box=None) -> float:
    """Volume under an object's cells of a top-down height map (m^3); box: its (row, col) slices, if known."""
    box = box or (slice(None), slice(None))
    return _column_volume_m3(np.asarray(grid_height_m)[box][np.asarray(grid_labels)[box] == label])


def _column_volume_m3(cell_heights_m) -> float:
    return float(np.nansum(np.clip(cell_heights_m, 0.0, None))) * CELL_M * CELL_M


def grip_estimate(network, label: int, rule: LabelGripRule,
                  density_kg_m3: float = OBJECT_DENSITY_KG_M3) -> GripEstimate:
    """The grip of object `label` of a TabletopNetworkView under a model's label rule."""
    view, box = network.view, network.boxes.get(label)
    mine = np.asarray(view.grid_labels)[box] == label if box else np.zeros((0,), bool)
    if not np.any(mine):
        raise ValueError(f"object {label} has no cell in the height map")
    mass = _column_volume_m3(np.asarray(view.grid_height_m)[box][mine]) * float(density_kg_m3)
    softest = float(np.min(np.asarray(network.moduli)[box][mine]))
    return GripEstimate(mass, softest, rule.grasp_finger_force_n(softest, mass))
