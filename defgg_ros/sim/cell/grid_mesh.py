"""Structured tetrahedral meshes of boxes, for the cell's soft boxes.

Why not fTetWild here: the cell simulates soft objects live next to a full
arm, and FEM cost grows steeply with the node count (a box resting on the
table, 5e-4 s steps, measured on this machine: 27 nodes 0.4 ms/step, 64
nodes 2.7 ms, 125 nodes 6 ms). A regular grid gives the coarsest mesh that
still has nodes on every face; each grid cube is split into six tets around
its main diagonal (conforming between neighbours).
"""
import hashlib
import itertools
from pathlib import Path

import numpy as np

from defgg_ros.atomic import atomic_path
from defgg_ros.sim import meshes

# Six tets sharing the cube diagonal v0 -> v7 (corners indexed by bits x, y, z).
_CUBE_TETS = ((0, 1, 3, 7), (0, 3, 2, 7), (0, 2, 6, 7), (0, 6, 4, 7), (0, 4, 5, 7), (0, 5, 1, 7))


def grid_counts(size_m, cell_size_m: float) -> tuple:
    """Nodes per axis: at least 2, spacing at most ~cell_size_m."""
    if cell_size_m <= 0:
        raise ValueError(f"cell_size_m must be > 0, got {cell_size_m}")
    return tuple(max(2, int(np.ceil(s / cell_size_m - 1e-9)) + 1) for s in size_m)


def box_grid(size_m, cell_size_m: float):
    """(nodes (N,3) centred at the origin, positively oriented tets (M,4))."""
    counts = grid_counts(size_m, cell_size_m)
    axes = [np.linspace(-s / 2, s / 2, n) for s, n in zip(size_m, counts)]
    nodes = np.array(list(itertools.product(*axes)))
    nx, ny, nz = counts

    def index(i, j, k):
        return (i * ny + j) * nz + k

    tets = []
    for i, j, k in itertools.product(range(nx - 1), range(ny - 1), range(nz - 1)):
        corners = [index(i + a, j + b, k + c) for a, b, c in itertools.product((0, 1), repeat=3)]
        # itertools order is (a, b, c) with c fastest; map to bit order x=1, y=2, z=4.
        by_bits = [corners[(bits & 1) * 4 + ((bits >> 1) & 1) * 2 + ((bits >> 2) & 1)] for bits in range(8)]
        tets += [[by_bits[v] for v in t] for t in _CUBE_TETS]
    tets = np.array(tets, dtype=np.int64)
    volumes = meshes.tet_volumes(nodes, tets)
    tets[volumes < 0] = tets[volumes < 0][:, [0, 2, 1, 3]]
    return nodes, tets


def box_tet_mesh(size_m, cell_size_m: float, folder: Path) -> meshes.TetMesh:
    """A TetMesh (the FEM library's type) of a box, files written into folder."""
    nodes, tets = box_grid(size_m, cell_size_m)
    digest = hashlib.sha256(np.round(nodes, 7).tobytes() + tets.tobytes()).hexdigest()[:20]
    folder = Path(folder)
    vtk_path, obj_path = folder / f"grid_{digest}.vtk", folder / f"grid_{digest}.obj"
    surface = meshes.boundary_faces(nodes, tets)
    if not vtk_path.exists():
        with atomic_path(vtk_path) as tmp:
            meshes.write_vtk(tmp, nodes, tets)
    if not obj_path.exists():
        with atomic_path(obj_path) as tmp:
            meshes.write_obj(tmp, nodes, surface)
    return meshes.TetMesh(nodes, tets, surface, digest, vtk_path, obj_path)
