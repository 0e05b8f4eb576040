"""Surface mesh -> coarse tetrahedral mesh (fTetWild), cached on disk by content hash.

The library objects' meshes are frozen in STORE_DIR (fTetWild is not
deterministic), so every machine simulates the same ones.

The tet mesh is the one geometry of an object: its nodes are the FEM soft
body, its boundary triangles are the rigid body's collision shape, the
rendered surface and the grasp sampler's surface. So a soft and a rigid
version of the same object have the same shape.

Why coarse: a soft body in contact costs ~12x its free-space step and the
cost grows with the node count (129 nodes ~6 ms/step, 500 nodes ~25 ms/step,
measured in docs/pybullet_fem.md). We aim at
TARGET_MAX_NODES nodes and coarsen until we get there.
"""
from __future__ import annotations

import contextlib
import hashlib
import os
import sys
import types
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from defgg_ros.atomic import atomic_path
from defgg_ros.sim.trimesh_import import trimesh

TARGET_MAX_NODES = 220
# (edge length factor, envelope epsilon) tried in order until the mesh has
# <= TARGET_MAX_NODES nodes. The envelope (relative to the bbox diagonal)
# bounds the node count more than the edge length does: 5e-3 kept ~400
# nodes on wavy blobs, 1e-2 (~0.8 mm on an 8 cm object) ~220-250.
COARSENING_STEPS = ((0.12, 5e-3), (0.15, 1e-2), (0.2, 1.5e-2), (0.25, 2e-2))
# Further steps, only for simulation meshes asked to be coarser than
# TARGET_MAX_NODES (the data generator's FEM mesh, docs/dataset.md): the
# default meshes stay exactly what they were.
EXTRA_COARSENING_STEPS = ((0.35, 3e-2), (0.5, 4e-2), (0.7, 5e-2))
# Finer steps, only for simulation meshes asked to be finer than TARGET_MAX_NODES (the signal pilots'
# try of ~500-node soft meshes): the first of these within the bound is taken.
REFINING_STEPS = ((0.06, 1.5e-3), (0.08, 2.5e-3), (0.1, 3.5e-3))
# A step coarser than the default may lose at most this fraction of the finest step's volume:
# coarsening shrinks curved surfaces (a 42-node sphere had 14 % less volume,
# hence mass) and collapsed the mug's thin wall (-95 %); then the mesh stays
# at the last step within it, above the node bound.
MAX_COARSENING_VOLUME_LOSS = 0.05
MESH_CACHE_ENV = "DEFGG_MESH_CACHE"
# The shipped, frozen tet meshes of the library objects (read-only; npz of nodes_m and tets).
STORE_DIR = Path(__file__).resolve().parent / "tet_meshes"
MESH_FORMAT_VERSION = "tet-v1"


class MeshError(ValueError):
    """A surface mesh that cannot become a valid tetrahedral mesh."""


@dataclass
class TetMesh:
    """Nodes (N,3, metres), positively oriented tets (M,4) and boundary triangles (K,3)."""
    nodes_m: np.ndarray
    tets: np.ndarray
    surface_faces: np.ndarray
    content_hash: str
    vtk_path: Path
    obj_path: Path

    def surface(self) -> trimesh.Trimesh:
        used = np.unique(self.surface_faces)
        remap = np.full(len(self.nodes_m), -1)
        remap[used] = np.arange(len(used))
        return trimesh.Trimesh(self.nodes_m[used], remap[self.surface_faces], process=False)

    @property
    def volume_m3(self) -> float:
        return float(tet_volumes(self.nodes_m, self.tets).sum())


def cache_dir() -> Path:
    default = Path(os.environ.get("XDG_CACHE_HOME", Path.home() / ".cache")) / "defgg_ros" / "meshes"
    path = Path(os.environ.get(MESH_CACHE_ENV, default))
    path.mkdir(parents=True, exist_ok=True)
    return path


def _import_pytetwild():
    # pytetwild imports pyvista at import time (undeclared dependency, see the
    # FEM notes); pyvista is installed here, but do not crash if it is not.
    try:
        import pyvista  # noqa: F401
    except ImportError:
        sys.modules.setdefault("pyvista", types.ModuleType("pyvista"))
    import pytetwild

    return pytetwild


def tet_volumes(nodes, tets) -> np.ndarray:
    a, b, c, d = (nodes[tets[:, i]] for i in range(4))
    return np.einsum("ij,ij->i", np.cross(b - a, c - a), d - a) / 6.0


def surface_hash(vertices, faces) -> str:
    h = hashlib.sha256(MESH_FORMAT_VERSION.encode())
    h.update(np.ascontiguousarray(np.round(vertices, 7), dtype=np.float64).tobytes())
    h.update(np.ascontiguousarray(faces, dtype=np.int64).tobytes())
    h.update(repr((TARGET_MAX_NODES, COARSENING_STEPS)).encode())
    return h.hexdigest()[:20]


def boundary_faces(nodes, tets) -> np.ndarray:
    """Triangles that belong to exactly one tet, oriented outwards."""
    local = np.array([[1, 2, 3], [0, 3, 2], [0, 1, 3], [0, 2, 1]])  # outward for positive tets
    faces = tets[:, local].reshape(-1, 3)
    key = np.sort(faces, axis=1)
    _, inverse, counts = np.unique(key, axis=0, return_inverse=True, return_counts=True)
    return faces[counts[inverse.ravel()] == 1]


def mesh_key(mesh: trimesh.Trimesh, max_nodes: int = TARGET_MAX_NODES, variant: str = "") -> str:
    """Name of a surface's tet mesh in the store and the cache."""
    digest = surface_hash(mesh.vertices, mesh.faces)
    if max_nodes != TARGET_MAX_NODES:
        digest = f"{digest}-n{max_nodes}"
    return f"{digest}-{variant}" if variant else digest


def tetrahedralize(mesh: trimesh.Trimesh, max_nodes: int = TARGET_MAX_NODES, variant: str = "") -> TetMesh:
    """The tet mesh of a closed surface mesh in metres: from the store, the cache, or fTetWild.

    fTetWild is not deterministic (the same surface gave 123-125 nodes in
    four runs), so the library objects' meshes are frozen in the shipped
    store (STORE_DIR, see freeze_meshes.py): every machine simulates the same
    discretization. `max_nodes` below TARGET_MAX_NODES asks for a coarser
    mesh; `variant` names an independent fTetWild run that bypasses the store
    (bench/bench_datagen.py measures what re-meshing does to the labels).
    """
    if len(mesh.faces) == 0 or not np.all(np.isfinite(mesh.vertices)):
        raise MeshError("empty mesh or non-finite vertices")
    if max_nodes < 4:
        raise MeshError(f"a tet mesh needs at least 4 nodes, asked for at most {max_nodes}")
    if max_nodes < TARGET_MAX_NODES:
        coarse = _tetrahedralize(mesh, max_nodes, variant)
        default = _tetrahedralize(mesh, TARGET_MAX_NODES, variant)
        # the volume rule can stop coarsening above the default mesh's node count: then keep the default
        return coarse if len(coarse.nodes_m) < len(default.nodes_m) else default
    return _tetrahedralize(mesh, max_nodes, variant)


def _tetrahedralize(mesh: trimesh.Trimesh, max_nodes: int, variant: str) -> TetMesh:
    digest = mesh_key(mesh, max_nodes, variant)
    folder = cache_dir()
    npz_path = STORE_DIR / f"{digest}.npz"
    if variant or not npz_path.exists():
        npz_path = folder / f"{digest}.npz"
        if not npz_path.exists():
            save_tet_mesh_file(npz_path, *_run_ftetwild(mesh, max_nodes))
    with np.load(npz_path, allow_pickle=False) as z:
        nodes, tets = z["nodes_m"], z["tets"]
    return tet_mesh_of(nodes, tets, digest)


def tet_mesh_of(nodes: np.ndarray, tets: np.ndarray, digest: str) -> TetMesh:
    """A TetMesh of these nodes and tets (digest: its name's stem), its VTK and OBJ written into the cache once."""
    folder = cache_dir()
    # The VTK the soft body loads and the OBJ are named after the nodes they hold, not only the surface: two
    # processes meshing one new surface at once (fTetWild is not deterministic) each write the npz, and a VTK
    # written from the first beside the second's npz made resetMeshData fail on every later activation (75 vs 64
    # nodes, the cell experiment's two runs, 2026-11-29).
    stem = f"{digest}-{hashlib.sha1(nodes.tobytes() + tets.tobytes()).hexdigest()[:10]}"
    vtk_path, obj_path = folder / f"{stem}.vtk", folder / f"{stem}.obj"
    surface = boundary_faces(nodes, tets)
    if not vtk_path.exists():
        with atomic_path(vtk_path) as tmp:
            write_vtk(tmp, nodes, tets)
    if not obj_path.exists():
        with atomic_path(obj_path) as tmp:
            write_obj(tmp, nodes, surface)
    return TetMesh(nodes, tets, surface, digest, vtk_path, obj_path)


def freeze(mesh: trimesh.Trimesh, max_nodes: int = TARGET_MAX_NODES) -> tuple:
    """Put a surface's tet mesh (the cached one if any) into the store; (path, newly added)."""
    digest = mesh_key(mesh, max_nodes)
    target = STORE_DIR / f"{digest}.npz"
    if target.exists():
        return target, False
    tet = tetrahedralize(mesh, max_nodes)
    STORE_DIR.mkdir(parents=True, exist_ok=True)
    with atomic_path(target) as tmp, open(tmp, "wb") as f:
        np.savez_compressed(f, nodes_m=tet.nodes_m, tets=tet.tets)
    return target, True


def _run_ftetwild(mesh, max_nodes: int = TARGET_MAX_NODES):
    pytetwild = _import_pytetwild()
    verts = np.asarray(mesh.vertices, dtype=np.float64)
    faces = np.asarray(mesh.faces, dtype=np.int32)
    nodes = tets = reference_volume = None
    steps = COARSENING_STEPS + (EXTRA_COARSENING_STEPS if max_nodes < TARGET_MAX_NODES else ())
    if max_nodes > TARGET_MAX_NODES:
        steps = REFINING_STEPS + COARSENING_STEPS
    for fac, eps in steps:
        step_nodes, step_tets = pytetwild.tetrahedralize(verts, faces, edge_length_fac=fac, coarsen=True,
                                                         epsilon=eps, num_threads=1, quiet=True)
        if step_tets is None or len(step_tets) == 0:
            break
        step_nodes = np.asarray(step_nodes, dtype=np.float64)
        step_tets = np.asarray(step_tets, dtype=np.int64)
        volume = float(np.abs(tet_volumes(step_nodes, step_tets)).sum())
        reference_volume = reference_volume or volume
        coarser_than_default = max_nodes < TARGET_MAX_NODES
        if coarser_than_default and volume < (1.0 - MAX_COARSENING_VOLUME_LOSS) * reference_volume:
            break
        nodes, tets = step_nodes, step_tets
        if len(nodes) <= max_nodes:
            break
    if tets is None or len(tets) == 0:
        raise MeshError("fTetWild produced no tetrahedra (is the surface closed?)")
    # fTetWild returns negatively oriented tets (FEM notes): flip them.
    vol = tet_volumes(nodes, tets)
    tets[vol < 0] = tets[vol < 0][:, [0, 2, 1, 3]]
    used = np.unique(tets)
    remap = np.full(len(nodes), -1)
    remap[used] = np.arange(len(used))
    return nodes[used], remap[tets]


def write_vtk(path, nodes, tets) -> None:
    """Legacy ASCII VTK, one point / one cell per line (what loadSoftBody reads)."""
    lines = ["# vtk DataFile Version 2.0", "defgg tet mesh", "ASCII", "DATASET UNSTRUCTURED_GRID",
             f"POINTS {len(nodes)} double"]
    lines += [f"{x:.8f} {y:.8f} {z:.8f}" for x, y, z in nodes]
    lines.append(f"CELLS {len(tets)} {5 * len(tets)}")
    lines += [f"4 {a} {b} {c} {d}" for a, b, c, d in tets]
    lines.append(f"CELL_TYPES {len(tets)}")
    lines += ["10"] * len(tets)
    Path(path).write_text("\n".join(lines) + "\n", encoding="ascii")


def write_obj(path, vertices, faces) -> None:
    lines = [f"v {x:.8f} {y:.8f} {z:.8f}" for x, y, z in vertices]
    lines += [f"f {a + 1} {b + 1} {c + 1}" for a, b, c in faces]
    Path(path).write_text("\n".join(lines) + "\n", encoding="ascii")


# V-HACD's settings for a rigid body's convex pieces: voxels of the decomposition and vertices per piece. The
# pieces come out larger than the surface (bench/bench_rigid_collision_fidelity.py measures by how much); the
# training labels' rigid trials were made with these, so they stay (docs/pybullet_fem.md "Rigid bodies").
VHACD_RESOLUTION = 200000
VHACD_MAX_VERTICES_PER_PIECE = 32


def convex_decomposition(tet: TetMesh, resolution: int = VHACD_RESOLUTION,
                         max_vertices_per_piece: int = VHACD_MAX_VERTICES_PER_PIECE) -> Path:
    """V-HACD convex pieces of the surface (dynamic rigid bodies need convex shapes), cached by the surface's
    content and the settings (a file of other settings is never taken for these)."""
    import pybullet as p

    out = tet.obj_path.with_name(f"{tet.content_hash}_vhacd_r{resolution}_v{max_vertices_per_piece}.obj")
    if not out.exists():
        log = out.with_suffix(".log")
        with atomic_path(out) as tmp:
            # pybullet.vhacd needs the file name to end in .obj
            tmp_obj = Path(str(tmp) + ".obj")
            with _stdout_silenced():  # V-HACD prints its progress from C
                p.vhacd(str(tet.obj_path), str(tmp_obj), str(log), resolution=resolution,
                        maxNumVerticesPerCH=max_vertices_per_piece)
            os.replace(tmp_obj, tmp)
        log.unlink(missing_ok=True)
    return out


@contextlib.contextmanager
def _stdout_silenced():
    sys.stdout.flush()
    saved = os.dup(1)
    with open(os.devnull, "w") as null:
        os.dup2(null.fileno(), 1)
    try:
        yield
    finally:
        os.dup2(saved, 1)
        os.close(saved)


def load_tet_mesh_file(path, scale=1.0, centred: bool = False) -> TetMesh:
    """A tetrahedral mesh saved as .npz (nodes_m (N,3) metres, tets (M,4) node indices: the store's format), as
    is: no fTetWild run, so every machine simulates this discretization (a library object's shipped mesh: the
    one its grasp labels were made with). scale: one factor or one per axis (> 0); centred: moved to centre its
    bounding box on the origin. MeshError when unusable."""
    path = Path(path)
    if path.suffix.lower() != ".npz":
        raise MeshError(f"{path}: a tet mesh file is .npz (nodes_m, tets)")
    try:
        with np.load(path, allow_pickle=False) as z:
            nodes = np.asarray(z["nodes_m"], dtype=np.float64) * np.asarray(scale, dtype=np.float64)
            tets = np.asarray(z["tets"], dtype=np.int64)
    except (OSError, KeyError, ValueError) as exc:
        raise MeshError(f"{path}: cannot read a tet mesh (nodes_m, tets): {type(exc).__name__}: {exc}") from None
    if nodes.ndim != 2 or nodes.shape[1] != 3 or tets.ndim != 2 or tets.shape[1] != 4 or len(tets) == 0:
        raise MeshError(f"{path}: nodes_m must be (N, 3) and tets (M, 4), got {nodes.shape} and {tets.shape}")
    if not np.all(np.isfinite(nodes)) or tets.min() < 0 or tets.max() >= len(nodes):
        raise MeshError(f"{path}: non-finite nodes or tet indices outside the {len(nodes)} nodes")
    if np.any(tet_volumes(nodes, tets) <= 0):
        raise MeshError(f"{path}: tets must be positively oriented with volume > 0")
    extent = np.ptp(nodes, axis=0).max()
    if not 0.005 <= extent <= 0.5:
        raise MeshError(f"{path}: extent {extent:.3f} m after scale {scale}; expected metres of a graspable object")
    if centred:
        nodes = nodes - (nodes.min(axis=0) + nodes.max(axis=0)) / 2
    digest = hashlib.sha256(nodes.tobytes() + tets.tobytes()).hexdigest()[:20]
    return tet_mesh_of(nodes, tets, f"file-{digest}")


def save_tet_mesh_file(path, nodes_m: np.ndarray, tets: np.ndarray) -> None:
    """Write nodes and tets as the .npz load_tet_mesh_file reads (atomically)."""
    with atomic_path(path) as tmp, open(tmp, "wb") as f:
        np.savez_compressed(f, nodes_m=np.asarray(nodes_m, dtype=np.float64), tets=np.asarray(tets, dtype=np.int64))


def load_user_mesh(path, scale: float = 1.0) -> trimesh.Trimesh:
    """Load a user's .obj/.stl surface mesh; raise MeshError when unusable."""
    path = Path(path)
    if path.suffix.lower() not in (".obj", ".stl"):
        raise MeshError(f"{path}: only .obj and .stl meshes are supported")
    try:
        mesh = trimesh.load(path, force="mesh", process=True)
    except Exception as exc:  # trimesh raises many types on bad files
        raise MeshError(f"{path}: cannot read mesh ({type(exc).__name__}: {exc})") from None
    if not isinstance(mesh, trimesh.Trimesh) or len(mesh.faces) == 0:
        raise MeshError(f"{path}: no triangles")
    mesh.apply_scale(scale)
    extent = np.ptp(mesh.vertices, axis=0).max()
    if not 0.005 <= extent <= 0.5:
        raise MeshError(f"{path}: extent {extent:.3f} m after scale {scale}; expected metres of a graspable object")
    return mesh
