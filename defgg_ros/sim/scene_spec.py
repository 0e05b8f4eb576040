"""The simulated cell's scene file (`sim_bringup/scenes/*.yaml`), parsed and validated.

A scene names the camera extrinsic, the table, an optional bin and the
objects (shape, size, pose on the table, Young's modulus, optional softer or
stiffer part). Objects stiffer than MAX_SOFT_BODY_YOUNGS_MODULUS_PA are
simulated as rigid bodies (PyBullet's FEM was unstable above it, see the FEM
notes); softer ones as FEM soft bodies. No rclpy and no PyBullet here.
"""
import math
from dataclasses import asdict, dataclass, field
from pathlib import Path

import numpy as np
import yaml

from defgg_ros.constants import (
    CAMERA_HEIGHT_ABOVE_TABLE_M,
    MAX_SOFT_BODY_YOUNGS_MODULUS_PA,
    YOUNGS_MODULUS_MAX_PA,
    YOUNGS_MODULUS_MIN_PA,
)

SHAPES = ("box", "cylinder", "mesh")
# A mesh object's file: a closed surface (meshed by fTetWild, not deterministic) or a tet mesh (nodes_m, tets) used
# as it is, e.g. a library object's shipped mesh (sim/cell/objects.cell_tet_mesh).
MESH_SUFFIXES = (".obj", ".stl", ".npz")
# Mass used when a scene does not give one: a light everyday object.
DEFAULT_OBJECT_MASS_KG = 0.1
# Soft boxes get a regular tet grid this coarse (see cell_grid_mesh: the FEM
# cost grows steeply with the node count); 0.025 m gives 27 nodes for 5 cm.
DEFAULT_FEM_CELL_SIZE_M = 0.025


class SceneError(ValueError):
    """A scene file is missing a field or holds an impossible value."""


@dataclass(frozen=True)
class PartSpec:
    """A part of an object with its own modulus (multi-material objects).

    The part is the slab of the object whose local x coordinate is >= x_from_m.
    """
    youngs_modulus_pa: float
    x_from_m: float


@dataclass(frozen=True)
class SceneObject:
    """An object of a scene: its shape and size, where it stands, its modulus and mass (the grasp trials' object is
    sim.objects.ObjectSpec: a library shape and a material)."""
    name: str
    shape: str
    size_m: tuple            # box: (x, y, z); cylinder: (diameter, height); mesh: scale (x, y, z)
    position_xy_m: tuple     # on the table, base frame
    yaw_rad: float
    youngs_modulus_pa: float
    mass_kg: float = DEFAULT_OBJECT_MASS_KG
    poisson_ratio: float | None = None   # None: the cell material's (cell_objects.MATERIAL)
    mesh_path: str = ""
    part: PartSpec | None = None
    fem_cell_size_m: float = DEFAULT_FEM_CELL_SIZE_M

    @property
    def is_soft(self) -> bool:
        return self.youngs_modulus_pa <= MAX_SOFT_BODY_YOUNGS_MODULUS_PA

    @property
    def height_m(self) -> float:
        return float(self.size_m[-1])


@dataclass(frozen=True)
class BinSpec:
    """An open box on the table to place objects into (rigid, static)."""
    center_xy_m: tuple
    inner_size_m: tuple      # (x, y, wall height)
    wall_thickness_m: float = 0.01


@dataclass(frozen=True)
class SceneSpec:
    name: str
    base_xyz_camera_m: tuple       # optical frame origin in panda_link0
    base_quat_camera_xyzw: tuple   # optical frame orientation in panda_link0
    table_size_m: tuple            # (x, y, thickness); top surface at z = 0
    table_center_xy_m: tuple
    objects: tuple = field(default_factory=tuple)
    bin: BinSpec | None = None

    @property
    def has_soft_objects(self) -> bool:
        return any(o.is_soft for o in self.objects)

    def to_json_dict(self) -> dict:
        """Plain dict (for the latched /fake_panda/scene topic)."""
        return asdict(self)


def _floats(value, n, what):
    try:
        out = tuple(float(v) for v in value)
    except (TypeError, ValueError):
        raise SceneError(f"{what} must be a list of {n} numbers, got {value!r}") from None
    if len(out) != n or not all(math.isfinite(v) for v in out):
        raise SceneError(f"{what} must be {n} finite numbers, got {value!r}")
    return out


def _positive(values, what):
    if any(v <= 0 for v in values):
        raise SceneError(f"{what} must be > 0, got {values}")
    return values


def _modulus(value, what):
    try:
        e_pa = float(value)
    except (TypeError, ValueError):
        raise SceneError(f"{what}: youngs_modulus_pa must be a number, got {value!r}") from None
    if not (YOUNGS_MODULUS_MIN_PA <= e_pa <= YOUNGS_MODULUS_MAX_PA):
        raise SceneError(
            f"{what}: youngs_modulus_pa={value!r} outside [{YOUNGS_MODULUS_MIN_PA:g}, {YOUNGS_MODULUS_MAX_PA:g}] Pa")
    return e_pa


def _parse_object(raw: dict, index: int, scene_dir: Path) -> SceneObject:
    if not isinstance(raw, dict):
        raise SceneError(f"objects[{index}] must be a mapping, got {raw!r}")
    name = str(raw.get("name") or "")
    what = f"object {index} ({name or 'unnamed'})"
    if not name:
        raise SceneError(f"{what}: missing name")
    shape = raw.get("shape")
    if shape not in SHAPES:
        raise SceneError(f"{what}: shape must be one of {SHAPES}, got {shape!r}")
    n_size = 2 if shape == "cylinder" else 3
    size = _positive(_floats(raw.get("size_m"), n_size, f"{what}: size_m"), f"{what}: size_m")
    mesh_path = ""
    if shape == "mesh":
        mesh_path = str((scene_dir / str(raw.get("mesh", ""))).resolve())
        if not Path(mesh_path).is_file():
            raise SceneError(f"{what}: mesh file {raw.get('mesh')!r} not found next to the scene")
        if Path(mesh_path).suffix.lower() not in MESH_SUFFIXES:
            raise SceneError(f"{what}: mesh file {raw.get('mesh')!r} must be one of {MESH_SUFFIXES} (a surface, "
                             "or a tet mesh .npz of nodes_m and tets simulated as it is)")
    part = None
    if raw.get("part") is not None:
        p = raw["part"]
        if not isinstance(p, dict):
            raise SceneError(f"{what}: part must be a mapping")
        part = PartSpec(_modulus(p.get("youngs_modulus_pa"), f"{what} part"),
                        float(p.get("x_from_m", 0.0)))
    mass_kg = float(raw.get("mass_kg", DEFAULT_OBJECT_MASS_KG))
    _positive((mass_kg,), f"{what}: mass_kg")
    nu = raw.get("poisson_ratio")
    nu = None if nu is None else float(nu)
    if nu is not None and not 0.0 <= nu < 0.5:
        raise SceneError(f"{what}: poisson_ratio must be in [0, 0.5), got {nu}")
    fem_cell_size_m = float(raw.get("fem_cell_size_m", DEFAULT_FEM_CELL_SIZE_M))
    _positive((fem_cell_size_m,), f"{what}: fem_cell_size_m")
    return SceneObject(
        fem_cell_size_m=fem_cell_size_m, name=name, shape=shape, size_m=size,
        position_xy_m=_floats(raw.get("position_xy_m"), 2, f"{what}: position_xy_m"),
        yaw_rad=float(raw.get("yaw_rad", 0.0)),
        youngs_modulus_pa=_modulus(raw.get("youngs_modulus_pa"), what),
        mass_kg=mass_kg, poisson_ratio=nu, mesh_path=mesh_path, part=part)


def _parse_camera(raw) -> tuple:
    if not isinstance(raw, dict):
        raise SceneError("base_T_camera must be a mapping with xyz and quat_xyzw")
    xyz = _floats(raw.get("xyz"), 3, "base_T_camera.xyz")
    quat = np.array(_floats(raw.get("quat_xyzw"), 4, "base_T_camera.quat_xyzw"))
    norm = np.linalg.norm(quat)
    if abs(norm - 1.0) > 1e-3:
        raise SceneError(f"base_T_camera.quat_xyzw must be a unit quaternion (norm {norm:.4f})")
    return xyz, tuple(float(v) for v in quat / norm)


def parse_scene(raw: dict, scene_dir: Path = Path(".")) -> SceneSpec:
    """Validate a scene mapping (as loaded from YAML) into a SceneSpec."""
    if not isinstance(raw, dict):
        raise SceneError(f"a scene must be a mapping, got {type(raw).__name__}")
    xyz, quat = _parse_camera(raw.get("base_T_camera", {
        "xyz": [0.5, 0.0, CAMERA_HEIGHT_ABOVE_TABLE_M], "quat_xyzw": [1.0, 0.0, 0.0, 0.0]}))
    table = raw.get("table", {})
    table_size = _positive(_floats(table.get("size_m", [1.2, 1.0, 0.05]), 3, "table.size_m"), "table.size_m")
    table_xy = _floats(table.get("center_xy_m", [0.45, 0.0]), 2, "table.center_xy_m")
    objects = tuple(_parse_object(o, i, scene_dir) for i, o in enumerate(raw.get("objects") or []))
    names = [o.name for o in objects]
    if len(set(names)) != len(names):
        raise SceneError(f"object names must be unique, got {names}")
    bin_spec = None
    if raw.get("bin") is not None:
        b = raw["bin"]
        bin_spec = BinSpec(_floats(b.get("center_xy_m"), 2, "bin.center_xy_m"),
                           _positive(_floats(b.get("inner_size_m"), 3, "bin.inner_size_m"), "bin.inner_size_m"),
                           float(b.get("wall_thickness_m", 0.01)))
    _check_on_table(table_size, table_xy, objects)
    return SceneSpec(name=str(raw.get("name", "scene")), base_xyz_camera_m=xyz, base_quat_camera_xyzw=quat,
                     table_size_m=table_size, table_center_xy_m=table_xy, objects=objects, bin=bin_spec)


def _table_bounds(table_size, table_xy) -> tuple:
    """(lo, hi) corners of the table's top in x, y and how to name it in a message."""
    lo = np.array(table_xy) - np.array(table_size[:2]) / 2
    hi = np.array(table_xy) + np.array(table_size[:2]) / 2
    return lo, hi, f"the table's top (x {lo[0]:.3f} ... {hi[0]:.3f} m, y {lo[1]:.3f} ... {hi[1]:.3f} m)"


def _check_on_table(table_size, table_xy, objects) -> None:
    """Every object stands on the table (one beside it would start in the air and fall to the floor)."""
    lo, hi, table = _table_bounds(table_size, table_xy)
    for o in objects:
        if np.any(np.array(o.position_xy_m) < lo) or np.any(np.array(o.position_xy_m) > hi):
            raise SceneError(f"object {o.name}: position_xy_m {list(o.position_xy_m)} is off {table}")


def scene_warnings(scene: SceneSpec) -> list:
    """What a scene allows but a cell would not be built like, one sentence each (the driver logs them).

    The bin's walls beyond the table: the table is the bin's floor, so an object placed over the edge rests
    on the FEM contact at the edge. With a bin reaching 7 cm beyond the table (the shipped scenes' once) the
    demo's rubber block fell off in 1 of 12 runs, 2 of 24 in-process placements
    (bench/bench_release_in_bin.py). A warning, not an error: a recorded session replays the scene it was
    recorded with (docs/sessions.md).
    """
    if scene.bin is None:
        return []
    lo, hi, table = _table_bounds(scene.table_size_m, scene.table_center_xy_m)
    b = scene.bin
    half = np.array(b.inner_size_m[:2]) / 2 + b.wall_thickness_m
    b_lo, b_hi = np.array(b.center_xy_m) - half, np.array(b.center_xy_m) + half
    if np.all(b_lo >= lo - 1e-9) and np.all(b_hi <= hi + 1e-9):
        return []
    return [f"the bin's walls (x {b_lo[0]:.3f} ... {b_hi[0]:.3f} m, y {b_lo[1]:.3f} ... {b_hi[1]:.3f} m) reach "
            f"beyond {table}: the table is the bin's floor, so an object placed over its edge rests on the edge "
            f"and may fall off; enlarge or move the table"]


def load_scene(path) -> SceneSpec:
    """Read and validate a scene YAML file; SceneError says what is wrong."""
    path = Path(path)
    if not path.is_file():
        raise SceneError(f"scene file {path} does not exist")
    try:
        raw = yaml.safe_load(path.read_text(encoding="utf-8"))
    except yaml.YAMLError as exc:
        raise SceneError(f"{path}: not valid YAML: {exc}") from None
    try:
        return parse_scene(raw, path.parent)
    except SceneError as exc:
        raise SceneError(f"{path}: {exc}") from None
