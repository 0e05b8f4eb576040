"""Bodies of the simulated cell: world reset, table, bin, scene objects, hand contacts.

Soft objects are FEM bodies of the physics core (physics.py, the same
settings as the grasp trials' objects); their tetrahedral meshes come from
the FEM library (`defgg_ros.sim.meshes`, `defgg_ros.sim.shapes`). Objects
stiffer than MAX_SOFT_BODY_YOUNGS_MODULUS_PA are rigid bodies (FEM at
E >= 2e7 Pa flung objects and forced the fingers open in the probe).
"""
import pybullet as p

from defgg_ros.sim import meshes, physics, shapes
from defgg_ros.sim.physics import SoftBodyError, reset_world, soft_nodes_m  # noqa: F401 - the cell's names
from defgg_ros.sim.scene_spec import BinSpec, SceneObject, SceneSpec

# The trial protocol whose labels the shipped weights learned (models/defgg_cnn.train.json's data_source,
# datasets/fem_v5: defgraspsim). The cell's objects and fingers are made of its material (object friction 0.7,
# pads 1.0, Poisson's ratio 0.3), so a grasp in the cell meets the contact the weights' labels were made with;
# test/sim/test_physics_core.py ties the two. The table and the bin keep the trials' table friction.
MATERIAL_PROTOCOL = "defgraspsim"
MATERIAL = physics.MATERIALS[MATERIAL_PROTOCOL]
FRICTION = physics.DEFAULT_FRICTION   # the table's and the bin's own coefficient
SOFT_COLLISION_MARGIN_M = physics.SOFT_COLLISION_MARGIN_M
TABLE_RGBA = (0.55, 0.45, 0.35, 1.0)
BIN_RGBA = (0.3, 0.3, 0.35, 1.0)
# Dropped from slightly above the table so nothing starts in penetration.
SPAWN_GAP_M = 0.002


def soft_time_step_s(youngs_modulus_pa: float) -> float:
    """The FEM library's stable step for one soft object (5e-4 s up to 2e5 Pa, 2.5e-4 s above)."""
    return physics.time_step_for([youngs_modulus_pa])


def time_step_for_scene(scene: SceneSpec, rigid_step_s: float) -> float:
    """The smallest step any soft object needs, or rigid_step_s without soft objects."""
    steps = [soft_time_step_s(o.youngs_modulus_pa) for o in scene.objects if o.is_soft]
    return min(steps, default=rigid_step_s)


def _static_box(client, half_extents, position, rgba):
    return physics.static_box(client, half_extents, position, rgba, FRICTION)


def add_table(client: int, scene: SceneSpec) -> int:
    sx, sy, thickness = scene.table_size_m
    cx, cy = scene.table_center_xy_m
    return _static_box(client, [sx / 2, sy / 2, thickness / 2], [cx, cy, -thickness / 2], TABLE_RGBA)


def add_bin(client: int, spec: BinSpec) -> list:
    """Four static walls around spec.center_xy_m on the table (the table is the bin floor)."""
    (cx, cy), (ix, iy, h), t = spec.center_xy_m, spec.inner_size_m, spec.wall_thickness_m
    walls = [([t / 2, iy / 2 + t, h / 2], [cx + s * (ix + t) / 2, cy, h / 2]) for s in (-1, 1)]
    walls += [([ix / 2, t / 2, h / 2], [cx, cy + s * (iy + t) / 2, h / 2]) for s in (-1, 1)]
    return [_static_box(client, half, pos, BIN_RGBA) for half, pos in walls]


def _surface_mesh(spec: SceneObject):
    if spec.shape == "box":
        return shapes.box(*spec.size_m)
    if spec.shape == "cylinder":
        return shapes.cylinder(*spec.size_m)
    if is_tet_mesh_file(spec):
        return cell_tet_mesh(spec).surface()
    mesh = meshes.load_user_mesh(spec.mesh_path)
    mesh.apply_scale(spec.size_m)
    return mesh


def is_tet_mesh_file(spec: SceneObject) -> bool:
    """A mesh object given as a tet mesh (.npz: a library object's shipped mesh), simulated as it is."""
    return spec.shape == "mesh" and spec.mesh_path.lower().endswith(".npz")


def cell_tet_mesh(spec: SceneObject) -> meshes.TetMesh:
    """The tet mesh the cell simulates a mesh object with, centred on its bounding box (metres): a .npz tet mesh
    as it is (the same discretization on every machine: fTetWild is not deterministic, and a library object's
    shipped mesh is the one its labels were made with), else fTetWild's mesh of the surface (.obj / .stl)."""
    if not is_tet_mesh_file(spec):
        return meshes.tetrahedralize(centred_surface_mesh(spec))
    return meshes.load_tet_mesh_file(spec.mesh_path, spec.size_m, centred=True)


def add_rigid_object(client: int, spec: SceneObject) -> int:
    """A dynamic rigid body resting on the table at its scene pose."""
    orientation = p.getQuaternionFromEuler([0, 0, spec.yaw_rad])
    position = [spec.position_xy_m[0], spec.position_xy_m[1], rigid_height_m(spec) / 2 + SPAWN_GAP_M]
    col, vis = _rigid_shapes(client, spec)
    body = p.createMultiBody(spec.mass_kg, col, vis, position, orientation, physicsClientId=client)
    physics.set_rigid_object_friction(client, body, [-1], MATERIAL, resting=True)
    return body


def rigid_height_m(spec: SceneObject) -> float:
    """The object's height: a mesh's size_m is its scale, so its height is the scaled surface's. (With the
    scale's z taken as the height, a 5 cm rigid mesh at scale 1 was dropped from 0.5 m and rolled 10 cm off its
    scene pose: the cell experiment's EGAD shapes, 2026-11-29.)"""
    if spec.shape == "mesh":
        lo, hi = centred_surface_mesh(spec).bounds
        return float(hi[2] - lo[2])
    return spec.height_m


def _rigid_shapes(client, spec: SceneObject):
    if spec.shape == "box":
        half = [s / 2 for s in spec.size_m]
        return (p.createCollisionShape(p.GEOM_BOX, halfExtents=half, physicsClientId=client),
                p.createVisualShape(p.GEOM_BOX, halfExtents=half, physicsClientId=client))
    if spec.shape == "cylinder":
        radius, height = spec.size_m[0] / 2, spec.size_m[1]
        return (p.createCollisionShape(p.GEOM_CYLINDER, radius=radius, height=height, physicsClientId=client),
                p.createVisualShape(p.GEOM_CYLINDER, radius=radius, length=height, physicsClientId=client))
    tet = cell_tet_mesh(spec)
    convex = meshes.convex_decomposition(tet)
    return (p.createCollisionShape(p.GEOM_MESH, fileName=str(convex), physicsClientId=client),
            p.createVisualShape(p.GEOM_MESH, fileName=str(tet.obj_path), physicsClientId=client))


def centred_surface_mesh(spec: SceneObject):
    """The object's closed surface, centred on its bounding box (metres)."""
    mesh = _surface_mesh(spec).copy()
    lo, hi = mesh.bounds
    mesh.apply_translation(-(lo + hi) / 2)
    return mesh


def load_soft_body(client: int, spec: SceneObject, tet, position, orientation) -> int:
    """The FEM body of a tet mesh with the physics core's settings, the same as a grasp trial's object."""
    parameters = physics.soft_body_parameters(spec.youngs_modulus_pa, poisson_ratio(spec), spec.mass_kg,
                                              MATERIAL.object_friction)
    try:
        return physics.load_soft_body(client, tet.vtk_path, position, orientation, parameters)
    except SoftBodyError as exc:
        raise SoftBodyError(f"{spec.name!r}: {exc}") from exc


def poisson_ratio(spec: SceneObject) -> float | None:
    """The scene object's own Poisson's ratio, else the cell material's (None: the core's default)."""
    return MATERIAL.poisson_ratio if spec.poisson_ratio is None else spec.poisson_ratio


def _force_on_a(c) -> tuple:
    """The contact's force on body A (N, a tuple): contactNormalOnB points from B to A, the normal force pushes A
    along it. Plain floats: the driver adds these up every 1 ms control period, where numpy's per-call cost on
    3-vectors exceeded the arithmetic's."""
    n, f1, f2 = c[7], c[11], c[13]
    return tuple(c[9] * n[i] + c[10] * f1[i] + c[12] * f2[i] for i in range(3))


def hand_contact_forces(client: int, robot: int, hand_links: list, active_soft_bodies: list) -> list:
    """[(contact point on the robot, force on the robot)] (tuples, m and N) for contacts on the hand and finger
    links. A contact between the hand and an FEM body is reported by both queries (its mirror image), so it counts
    twice: docs/pybullet_fem.md, "The hand's contact force" (kept as it was, measured 2026-12-03)."""
    out = []
    for link in hand_links:
        for c in p.getContactPoints(bodyA=robot, linkIndexA=link, physicsClientId=client):
            if c[2] != robot:
                out.append((c[5], _force_on_a(c)))
    for body in active_soft_bodies:
        for c in p.getContactPoints(bodyA=body, bodyB=robot, physicsClientId=client):
            if c[4] in hand_links:
                out.append((c[6], tuple(-v for v in _force_on_a(c))))
    return out
