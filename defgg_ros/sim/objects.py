"""Objects: geometry (ObjectShape), material (ObjectSpec) and loading into PyBullet.

Soft or rigid: a part with E <= MAX_SOFT_BODY_YOUNGS_MODULUS_PA becomes an
FEM soft body (Neo-Hookean, the physics core's settings: physics.py). Stiffer parts
become rigid bodies, because PyBullet's FEM was unstable for E >= 2e7 Pa on
this machine (objects flung, fingers forced open; see
docs/pybullet_fem.md and docs/dataset.md). At 2e9 Pa and
2-20 N over ~5 cm^2 the strain is ~1e-5, so a rigid body is physically fair.

Multi-material objects have two parts. PyBullet gives one material per soft
body and can anchor soft nodes only to rigid bodies, so a supported
combination is: both parts rigid, both parts soft with the same E (one soft
body), or one soft part anchored to a rigid part. Two soft parts of
different E raise UnsupportedMaterial instead of silently merging them.
"""
from __future__ import annotations

import functools
import math
from dataclasses import dataclass, field, replace

import numpy as np
import pybullet as p

from defgg_ros.constants import (
    MAX_SOFT_BODY_YOUNGS_MODULUS_PA,
    OBJECT_DENSITY_KG_M3,
    POISSON_RATIO,
    TRAINING_YOUNGS_MODULI_PA,
)
from defgg_ros.sim import library, meshes, physics
from defgg_ros.sim.trimesh_import import trimesh
from defgg_ros.stiffness import check_youngs_modulus

DEFAULT_DENSITY_KG_M3 = OBJECT_DENSITY_KG_M3
# Soft nodes closer than this to a rigid part are anchored to it (multi-material).
ANCHOR_DISTANCE_M = 0.003
OBJECT_FRICTION = physics.DEFAULT_FRICTION
# Objects are loaded this far above the table so they never start in contact.
DROP_GAP_M = 0.0005


class UnsupportedMaterial(ValueError):
    """A material combination PyBullet's FEM cannot represent."""


class UnknownObject(KeyError):
    """An object or set name that the library does not have."""


@dataclass(frozen=True)
class ObjectShape:
    """Geometry only. `build` returns one list of overlapping surface pieces per part.

    `max_tet_nodes` bounds the tet meshes' node count; `coarsened(n)` is the
    same shape with a coarser FEM mesh. `mesh_variant` names an independent
    fTetWild run instead of the shipped mesh (meshes.tetrahedralize).
    """
    name: str
    set_name: str
    build: object = field(repr=False, compare=False)
    max_tet_nodes: int = meshes.TARGET_MAX_NODES
    mesh_variant: str = ""

    def coarsened(self, max_tet_nodes: int | None) -> ObjectShape:
        """This shape meshed with at most `max_tet_nodes` nodes per part (None: unchanged)."""
        if max_tet_nodes is None or max_tet_nodes == self.max_tet_nodes:
            return self
        return replace(self, max_tet_nodes=int(max_tet_nodes))

    def remeshed(self, variant: str) -> ObjectShape:
        """The same surface through another fTetWild run (not the shipped mesh)."""
        return replace(self, mesh_variant=variant)

    @functools.cached_property
    def _surfaces(self) -> tuple:
        """Surface per part in the object frame: resting on z = 0, xy bbox centred."""
        surfaces = [trimesh.util.concatenate(pieces) for pieces in self.build()]
        lo = np.min([m.bounds[0] for m in surfaces], axis=0)
        hi = np.max([m.bounds[1] for m in surfaces], axis=0)
        shift = np.array([-(lo[0] + hi[0]) / 2, -(lo[1] + hi[1]) / 2, -lo[2]])
        for m in surfaces:
            m.apply_translation(shift)
        return tuple(surfaces)

    @functools.cached_property
    def tet_parts(self) -> tuple:
        """Tet mesh per part, object frame."""
        return tuple(meshes.tetrahedralize(m, self.max_tet_nodes, self.mesh_variant) for m in self._surfaces)

    @functools.cached_property
    def union_tet(self) -> meshes.TetMesh:
        """One tet mesh of all parts together (one soft body of one material)."""
        if len(self._surfaces) == 1:
            return self.tet_parts[0]
        return meshes.tetrahedralize(trimesh.util.concatenate(list(self._surfaces)), self.max_tet_nodes,
                                     self.mesh_variant)

    @property
    def n_parts(self) -> int:
        return len(self.tet_parts)

    def surface(self) -> trimesh.Trimesh:
        """Union (concatenation) of the parts' boundary surfaces, object frame."""
        return trimesh.util.concatenate([t.surface() for t in self.tet_parts])

    @property
    def height_m(self) -> float:
        return float(max(t.nodes_m[:, 2].max() for t in self.tet_parts))


@dataclass(frozen=True)
class ObjectSpec:
    """An object made of a material: E (Pa) and Poisson ratio, optionally a second part's E."""
    shape: ObjectShape
    youngs_modulus_pa: float
    poisson_ratio: float = POISSON_RATIO
    part_youngs_modulus_pa: float | None = None
    density_kg_m3: float = DEFAULT_DENSITY_KG_M3

    def __post_init__(self):
        check_youngs_modulus(self.youngs_modulus_pa)
        if self.part_youngs_modulus_pa is not None:
            check_youngs_modulus(self.part_youngs_modulus_pa)
        if not 0.0 <= self.poisson_ratio < 0.5:
            raise ValueError(f"Poisson ratio must be in [0, 0.5), got {self.poisson_ratio}")

    @property
    def name(self) -> str:
        return self.shape.name

    def part_moduli_pa(self) -> list:
        """E of each part: part 0 has youngs_modulus_pa, part 1 its own E if given."""
        moduli = [float(self.youngs_modulus_pa)] * self.shape.n_parts
        if self.part_youngs_modulus_pa is not None:
            if self.shape.n_parts < 2:
                raise UnsupportedMaterial(f"{self.name} has one part; part_youngs_modulus_pa needs two")
            moduli[1] = float(self.part_youngs_modulus_pa)
        return moduli

    def with_modulus(self, youngs_modulus_pa: float) -> ObjectSpec:
        return replace(self, youngs_modulus_pa=youngs_modulus_pa)


def is_soft(youngs_modulus_pa: float) -> bool:
    return youngs_modulus_pa <= MAX_SOFT_BODY_YOUNGS_MODULUS_PA


def simulation_shape(shape: ObjectShape, youngs_modulus_pa: float, max_tet_nodes: int | None) -> ObjectShape:
    """The shape to simulate: a coarser FEM mesh only for soft bodies. A rigid body gains no speed
    from it (0.3 s CPU per trial either way) and its faceted collision shape changes the grip: a
    rigid sphere that slipped at 1.6 m/s^2 on the shipped mesh held 25.7 m/s^2 on a coarse one."""
    return shape.coarsened(max_tet_nodes) if is_soft(youngs_modulus_pa) else shape


def object_set(set_name: str) -> list:
    """ObjectShapes of a named set ("train", "common", "adversarial"), sorted by name."""
    if set_name not in library.OBJECT_SETS:
        raise UnknownObject(f"unknown object set {set_name!r}; known: {sorted(library.OBJECT_SETS)}")
    return [_shape(set_name, name) for name in sorted(library.OBJECT_SETS[set_name])]


@functools.cache
def _shape(set_name: str, name: str) -> ObjectShape:
    return ObjectShape(name, set_name, library.OBJECT_SETS[set_name][name])


def get_shape(name: str) -> ObjectShape:
    for set_name, builders in library.OBJECT_SETS.items():
        if name in builders:
            return _shape(set_name, name)
    raise UnknownObject(f"no object named {name!r}")


def shape_from_mesh_file(path, name: str | None = None, scale: float = 1.0) -> ObjectShape:
    """An ObjectShape from a user's .obj/.stl file (metres after `scale`)."""
    from pathlib import Path

    mesh = meshes.load_user_mesh(path, scale)
    return ObjectShape(name or Path(path).stem, "user", lambda: [[mesh.copy()]])


def training_specs(set_name: str = "train", moduli_pa=TRAINING_YOUNGS_MODULI_PA) -> list:
    return [ObjectSpec(shape, e) for shape in object_set(set_name) for e in moduli_pa]


@dataclass
class LoadedPart:
    body_id: int
    link_index: int          # -1 for a base / soft body
    youngs_modulus_pa: float
    soft: bool
    mass_kg: float


@dataclass
class LoadedObject:
    """Body ids of one loaded object plus what is needed to save/restore it."""
    client: int
    spec: ObjectSpec
    parts: list
    world_T_object: np.ndarray

    @property
    def body_ids(self) -> list:
        return sorted({part.body_id for part in self.parts})

    @property
    def soft_body_ids(self) -> list:
        return sorted({part.body_id for part in self.parts if part.soft})

    @property
    def mass_kg(self) -> float:
        return float(sum(part.mass_kg for part in self.parts))

    def node_positions(self, body_id: int) -> np.ndarray:
        _, verts = p.getMeshData(body_id, -1, flags=p.MESH_DATA_SIMULATION_MESH, physicsClientId=self.client)
        return np.asarray(verts, dtype=np.float64)

    def centroid_m(self) -> np.ndarray:
        """Mass-weighted centre of the object (soft: mean of nodes)."""
        total, acc = 0.0, np.zeros(3)
        for body in self.body_ids:
            part_mass = sum(pt.mass_kg for pt in self.parts if pt.body_id == body)
            acc += part_mass * self._body_centre(body)
            total += part_mass
        return acc / total

    def _body_centre(self, body: int) -> np.ndarray:
        if body in self.soft_body_ids:
            return self.node_positions(body).mean(axis=0)
        return np.asarray(p.getBasePositionAndOrientation(body, physicsClientId=self.client)[0])

    def tracked_points(self) -> list:
        """Per body: the FEM nodes (soft) or the base position (rigid), as (n, 3) arrays."""
        return [self.node_positions(b) if b in self.soft_body_ids else np.array([self._body_centre(b)])
                for b in self.body_ids]

    def is_finite(self, max_extent_m: float = 1.0, points: list | None = None) -> bool:
        """False when the simulation exploded: non-finite or runaway nodes/poses."""
        for pts in self.tracked_points() if points is None else points:
            if not np.all(np.isfinite(pts)) or np.ptp(pts, axis=0).max() > max_extent_m:
                return False
            if np.abs(pts).max() > 10.0:
                return False
        return True

    def save_state(self) -> dict:
        """Node positions (soft) and poses (rigid). saveState/restoreState do not cover soft nodes."""
        state = {}
        for body in self.body_ids:
            if body in self.soft_body_ids:
                state[body] = ("soft", self.node_positions(body))
            else:
                pos, orn = p.getBasePositionAndOrientation(body, physicsClientId=self.client)
                state[body] = ("rigid", (pos, orn))
        return state

    def restore_state(self, state: dict) -> None:
        for body, (kind, value) in state.items():
            if kind == "soft":
                p.resetMeshData(body, vertices=value.tolist(), physicsClientId=self.client)
            else:
                p.resetBasePositionAndOrientation(body, *value, physicsClientId=self.client)
            # On a soft body this zeroes every node velocity (FEM notes).
            p.resetBaseVelocity(body, [0, 0, 0], [0, 0, 0], physicsClientId=self.client)


def object_pose(position_xy_m, yaw_rad, table_top_z_m=0.0) -> np.ndarray:
    """world_T_object for an object resting on the table at (x, y), rotated by yaw."""
    c, s = math.cos(yaw_rad), math.sin(yaw_rad)
    pose = np.eye(4)
    pose[:3, :3] = [[c, -s, 0], [s, c, 0], [0, 0, 1]]
    pose[:3, 3] = [position_xy_m[0], position_xy_m[1], table_top_z_m + DROP_GAP_M]
    return pose


def load_object(client: int, spec: ObjectSpec, position_xy_m=(0.0, 0.0), yaw_rad: float = 0.0,
                table_top_z_m: float = 0.0, friction: float = OBJECT_FRICTION) -> LoadedObject:
    """Load `spec` resting on the table; soft parts as FEM soft bodies, stiff ones rigid.

    The world must be a deformable world (world.create_world) when any part is soft. `friction` is the
    object's own coefficient; Bullet multiplies it by the other body's in every contact.
    """
    moduli = spec.part_moduli_pa()
    softness = [is_soft(e) for e in moduli]
    if sum(softness) == 2 and moduli[0] != moduli[1]:
        raise UnsupportedMaterial(
            f"{spec.name}: two soft parts with different E ({moduli[0]:.0e}, {moduli[1]:.0e} Pa); PyBullet "
            "soft bodies carry one material and cannot be anchored to each other")
    world_T_object = object_pose(position_xy_m, yaw_rad, table_top_z_m)
    tets = spec.shape.tet_parts
    masses = [t.volume_m3 * spec.density_kg_m3 for t in tets]
    parts: list = [None] * len(tets)
    rigid_idx = [i for i, soft in enumerate(softness) if not soft]
    if rigid_idx:
        body = _load_rigid(client, [tets[i] for i in rigid_idx], [masses[i] for i in rigid_idx], world_T_object,
                           friction)
        for link, i in enumerate(rigid_idx):
            parts[i] = LoadedPart(body, link - 1, moduli[i], False, masses[i])
    soft_idx = [i for i, soft in enumerate(softness) if soft]
    if soft_idx:
        soft_tet = tets[soft_idx[0]] if len(soft_idx) == 1 else spec.shape.union_tet
        body = _load_soft(client, soft_tet, sum(masses[i] for i in soft_idx), moduli[soft_idx[0]],
                          spec.poisson_ratio, world_T_object, friction)
        for i in soft_idx:
            parts[i] = LoadedPart(body, -1, moduli[i], True, masses[i])
        if rigid_idx:
            rigid_body = parts[rigid_idx[0]].body_id
            _anchor(client, body, rigid_body, soft_tet, [tets[i] for i in rigid_idx], world_T_object)
            # Anchored nodes sit on the rigid part's face; left colliding, contact and anchors
            # fight and the object was flung ~1.7 m in 0.2 s (measured). So the pair never collides.
            for link in range(-1, len(rigid_idx) - 1):
                p.setCollisionFilterPair(rigid_body, body, link, -1, 0, physicsClientId=client)
    return LoadedObject(client, spec, parts, world_T_object)


def _transform(pose, pts):
    return pts @ pose[:3, :3].T + pose[:3, 3]


def _quat(pose):
    yaw = math.atan2(pose[1, 0], pose[0, 0])
    return p.getQuaternionFromEuler([0, 0, yaw])


def _load_soft(client, tet, mass_kg, youngs_modulus_pa, poisson_ratio, world_T_object, friction) -> int:
    parameters = physics.soft_body_parameters(youngs_modulus_pa, poisson_ratio, mass_kg, friction)
    with meshes._stdout_silenced():  # loadSoftBody prints node/tet counts from C
        return physics.load_soft_body(client, tet.vtk_path, world_T_object[:3, 3].tolist(), _quat(world_T_object),
                                      parameters)


def _load_rigid(client, tets, masses, world_T_object, friction) -> int:
    """One rigid multibody: part 0 as the base, further parts as fixed links (own segmentation ids)."""
    shapes_ = []
    for tet in tets:
        vhacd = meshes.convex_decomposition(tet)
        col = p.createCollisionShape(p.GEOM_MESH, fileName=str(vhacd), physicsClientId=client)
        vis = p.createVisualShape(p.GEOM_MESH, fileName=str(tet.obj_path), physicsClientId=client)
        shapes_.append((col, vis))
    coms = [tet.nodes_m.mean(axis=0) for tet in tets]
    extra = len(tets) - 1
    body = p.createMultiBody(
        baseMass=masses[0], baseCollisionShapeIndex=shapes_[0][0], baseVisualShapeIndex=shapes_[0][1],
        basePosition=world_T_object[:3, 3].tolist(), baseOrientation=_quat(world_T_object),
        baseInertialFramePosition=coms[0].tolist(),
        linkMasses=masses[1:], linkCollisionShapeIndices=[s[0] for s in shapes_[1:]],
        linkVisualShapeIndices=[s[1] for s in shapes_[1:]], linkPositions=[[0, 0, 0]] * extra,
        linkOrientations=[[0, 0, 0, 1]] * extra, linkInertialFramePositions=[c.tolist() for c in coms[1:]],
        linkInertialFrameOrientations=[[0, 0, 0, 1]] * extra, linkParentIndices=[0] * extra,
        linkJointTypes=[p.JOINT_FIXED] * extra, linkJointAxis=[[0, 0, 1]] * extra, physicsClientId=client)
    physics.set_friction(client, body, range(-1, extra), friction)
    return body


def _anchor(client, soft_body, rigid_body, soft_tet, rigid_tets, world_T_object) -> int:
    """Anchor soft nodes lying on/inside the rigid part's bounding box; return how many."""
    count = 0
    for node_index, node in enumerate(soft_tet.nodes_m):
        for link, tet in enumerate(rigid_tets):
            lo, hi = tet.nodes_m.min(axis=0) - ANCHOR_DISTANCE_M, tet.nodes_m.max(axis=0) + ANCHOR_DISTANCE_M
            if np.all(node >= lo) and np.all(node <= hi):
                p.createSoftBodyAnchor(soft_body, node_index, rigid_body, link - 1, physicsClientId=client)
                count += 1
                break
    if count == 0:
        raise UnsupportedMaterial("soft part does not touch the rigid part: nothing to anchor")
    return count
