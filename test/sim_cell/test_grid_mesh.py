"""Structured box tet meshes for the cell's soft boxes."""
import numpy as np
import pytest

from defgg_ros.sim import meshes
from defgg_ros.sim.cell.grid_mesh import box_grid, box_tet_mesh, grid_counts


@pytest.mark.parametrize("size", [(0.05, 0.05, 0.05), (0.08, 0.04, 0.03), (0.02, 0.1, 0.06)])
def test_grid_fills_the_box_with_positive_tets(size):
    nodes, tets = box_grid(size, 0.025)
    volumes = meshes.tet_volumes(nodes, tets)
    assert np.all(volumes > 0)
    assert volumes.sum() == pytest.approx(np.prod(size), rel=1e-9)
    np.testing.assert_allclose(np.ptp(nodes, axis=0), size)


def test_counts_and_surface(tmp_path):
    assert grid_counts((0.05, 0.05, 0.05), 0.025) == (3, 3, 3)
    tet = box_tet_mesh((0.05, 0.05, 0.05), 0.025, tmp_path)
    assert len(tet.nodes_m) == 27 and tet.vtk_path.exists()
    # A conforming grid has only the outer faces as boundary: 6 faces x 4 squares x 2 triangles.
    assert len(tet.surface_faces) == 48


def test_bad_cell_size():
    with pytest.raises(ValueError, match="cell_size_m"):
        grid_counts((0.05, 0.05, 0.05), 0.0)
