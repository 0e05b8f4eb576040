"""The section the pads squeeze, from the height map (the squeeze's section law: defgg_ros/section_model.py).

The object's outline at the fingertips' height, seen from above, resampled into the grasp's frame on square
cells of SECTION_CELL_M: columns along the closing direction, rows across it, the grasp line the middle row. Each
cell also carries the object's height there (the height map's, above the table: a camera above sees no undercut,
so an object is taken to stand on the table under its top). Only the parts connected to what lies under the pads
count: a neighbour in the window is not squeezed.
"""
from __future__ import annotations

import cv2
import numpy as np

from defgg_ros.constants import GRIPPER_MAX_WIDTH_M
from defgg_ros.perception.tabletop import CELL_M

SECTION_CELL_M = 0.003          # 3 mm: a star prism's arm spans 3-6 cells; the FEM solves in ~1 s
SUBSAMPLES = 3                  # height-map samples per section cell and axis (occupancy >= half: in)
HALF_ALONG_M = GRIPPER_MAX_WIDTH_M / 2 + 0.006     # the hand's opening, and a margin
HALF_ACROSS_M = 0.05            # the section's reach across the grasp line (an arm beside the pads still loads)


def perceived_section(grid_height_m: np.ndarray, grid_labels: np.ndarray, label: int, centre_rc, direction_rc,
                      tip_height_m: float, cell_m: float = SECTION_CELL_M) -> tuple[np.ndarray, np.ndarray]:
    """(mask, height_m) of the section (module doc); grid_*: the view's height map (CELL_M cells); centre_rc,
    direction_rc: the grasp's centre and closing direction in cells (row, col); tip_height_m: the fingertips'
    height above the table. The mask is empty when nothing of the object stands that high near the grasp."""
    along_dir = np.asarray(direction_rc, float)
    along_dir = along_dir / np.linalg.norm(along_dir)
    across_dir = np.array([-along_dir[1], along_dir[0]])
    n_along, n_across = (int(round(2 * half / cell_m)) for half in (HALF_ALONG_M, HALF_ACROSS_M))
    sub = cell_m / SUBSAMPLES
    along = (np.arange(n_along * SUBSAMPLES) + 0.5) * sub - n_along * cell_m / 2
    across = (np.arange(n_across * SUBSAMPLES) + 0.5) * sub - n_across * cell_m / 2
    points = (np.asarray(centre_rc, float) + (along[None, :, None] * along_dir
                                              + across[:, None, None] * across_dir) / CELL_M)
    rows, cols = (np.rint(points[..., i]).astype(int) for i in (0, 1))
    inside = (rows >= 0) & (rows < grid_labels.shape[0]) & (cols >= 0) & (cols < grid_labels.shape[1])
    rows, cols = np.where(inside, rows, 0), np.where(inside, cols, 0)
    height = np.where(inside, grid_height_m[rows, cols], 0.0)
    mine = inside & (grid_labels[rows, cols] == label) & (height >= tip_height_m)
    occupancy = _blocks_mean(mine.astype(float))
    mean_height = _blocks_mean(np.where(mine, height, 0.0)) / np.maximum(occupancy, 1e-9)
    mask = _under_pads_connected(occupancy >= 0.5)
    return mask, np.where(mask, mean_height, 0.0)


def _blocks_mean(values: np.ndarray) -> np.ndarray:
    """Means over SUBSAMPLES x SUBSAMPLES blocks."""
    r, c = values.shape[0] // SUBSAMPLES, values.shape[1] // SUBSAMPLES
    return values[:r * SUBSAMPLES, :c * SUBSAMPLES].reshape(r, SUBSAMPLES, c, SUBSAMPLES).mean(axis=(1, 3))


def _under_pads_connected(mask: np.ndarray) -> np.ndarray:
    """The parts of the mask (4-connected) that reach the middle row: what the pads load."""
    count, parts = cv2.connectedComponents(mask.astype(np.uint8), connectivity=4)
    loaded = set(np.unique(parts[mask.shape[0] // 2][mask[mask.shape[0] // 2]]).tolist())
    return np.isin(parts, sorted(loaded)) & mask if count > 1 else mask
