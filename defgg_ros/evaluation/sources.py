"""Which objects an evaluation grasps, and at which Young's moduli.

Named sets come from the simulator's library ("common", "adversarial"; the
"train" set is refused: evaluating on training objects would flatter the
model). ``--objects DIR`` evaluates a folder of .obj/.stl meshes; an optional
YAML file (``DIR/moduli.yaml`` or ``--moduli-yaml``) gives per-object moduli
and scales::

    youngs_modulus_pa: [2.0e4, 2.0e9]   # default for every mesh (else --moduli)
    scale: 0.001                         # mesh units -> metres (default 1.0)
    objects:
      sponge: {youngs_modulus_pa: [2.0e5], scale: 0.01}   # key = file stem
      block.stl: 2.0e6                                    # or file name, one value

Multi-material objects of the library (two parts): the table's modulus is
the modulus of part 1 (the part whose stiffness "can vary", like the
paper's object 7); part 0 stays at MULTI_MATERIAL_BASE_E_PA.
"""
from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path

import yaml

from defgg_ros.constants import TRAINING_YOUNGS_MODULI_PA, YOUNGS_MODULUS_MAX_PA, YOUNGS_MODULUS_MIN_PA
from defgg_ros.sim import objects as sim_objects
from defgg_ros.stiffness import InvalidYoungsModulus, check_youngs_modulus

EVAL_SETS = ("common", "adversarial")
# The stiff part of a two-part object: the paper's stiffest material.
MULTI_MATERIAL_BASE_E_PA = max(TRAINING_YOUNGS_MODULI_PA)
MESH_SUFFIXES = (".obj", ".stl")
DEFAULT_YAML_NAME = "moduli.yaml"


class SourceError(ValueError):
    """An object set, mesh folder or moduli file that cannot be evaluated."""


@dataclass(frozen=True)
class EvalObject:
    """One object to evaluate: its shape, its set and the moduli (Pa) of its table rows."""
    name: str
    set_name: str
    shape: object = field(repr=False, compare=False)   # defgg_ros.sim.objects.ObjectShape
    moduli_pa: tuple = TRAINING_YOUNGS_MODULI_PA
    mesh_path: str = ""          # user meshes: rebuilt from the file in worker processes
    mesh_scale: float = 1.0

    @property
    def ref(self) -> tuple:
        """Picklable handle for worker processes (see shape_from_ref)."""
        return (self.set_name, self.name, self.mesh_path, self.mesh_scale)

    @property
    def multi_material(self) -> bool:
        return n_parts(self.shape) > 1

    def spec(self, youngs_modulus_pa: float, part0_youngs_modulus_pa: float | None = None):
        """The simulator's ObjectSpec at a table modulus (see the module docstring for two parts)."""
        return make_spec(self.shape, youngs_modulus_pa, part0_youngs_modulus_pa)


def n_parts(shape) -> int:
    """Parts of a shape, counted on its surface builder (no tetrahedralisation needed)."""
    return len(shape.build())


def make_spec(shape, youngs_modulus_pa: float, part0_youngs_modulus_pa: float | None = None):
    """ObjectSpec of `shape` at a table modulus; two-part shapes vary part 1, part 0 stays stiff."""
    if n_parts(shape) < 2:
        return sim_objects.ObjectSpec(shape, youngs_modulus_pa)
    base = MULTI_MATERIAL_BASE_E_PA if part0_youngs_modulus_pa is None else part0_youngs_modulus_pa
    return sim_objects.ObjectSpec(shape, base, part_youngs_modulus_pa=youngs_modulus_pa)


def check_moduli(values, what: str = "moduli") -> tuple:
    """Validated tuple of Young's moduli in Pa (inside the encodable range)."""
    if isinstance(values, (int, float, str)):
        values = [values]
    out = []
    for v in values:
        try:
            e = check_youngs_modulus(float(v))
        except (TypeError, ValueError, InvalidYoungsModulus) as exc:
            raise SourceError(f"{what}: {exc}") from None
        if not YOUNGS_MODULUS_MIN_PA <= e <= YOUNGS_MODULUS_MAX_PA:
            raise SourceError(f"{what}: {e:g} Pa outside [{YOUNGS_MODULUS_MIN_PA:g}, {YOUNGS_MODULUS_MAX_PA:g}] Pa")
        out.append(e)
    if not out:
        raise SourceError(f"{what}: no modulus given")
    return tuple(out)


def named_set(set_name: str, moduli_pa=TRAINING_YOUNGS_MODULI_PA, only=None) -> list:
    """EvalObjects of a held-out library set, optionally restricted to names in `only`."""
    if set_name not in EVAL_SETS:
        raise SourceError(f"object set {set_name!r} cannot be evaluated; choose from {', '.join(EVAL_SETS)}")
    moduli = check_moduli(moduli_pa)
    shapes = sim_objects.object_set(set_name)
    if only:
        missing = set(only) - {s.name for s in shapes}
        if missing:
            raise SourceError(f"set {set_name!r} has no object(s) {sorted(missing)}")
        shapes = [s for s in shapes if s.name in only]
    return [EvalObject(s.name, set_name, s, moduli) for s in shapes]


def mesh_folder(folder, moduli_pa=TRAINING_YOUNGS_MODULI_PA, yaml_path=None) -> list:
    """EvalObjects for every .obj/.stl in `folder` (set name "user")."""
    folder = Path(folder)
    if not folder.is_dir():
        raise SourceError(f"--objects {folder}: not a directory")
    meshes = sorted(p for p in folder.iterdir() if p.suffix.lower() in MESH_SUFFIXES)
    if not meshes:
        raise SourceError(f"--objects {folder}: no .obj or .stl files")
    config = _read_yaml(yaml_path or folder / DEFAULT_YAML_NAME, required=yaml_path is not None)
    default_moduli = check_moduli(config.get("youngs_modulus_pa", moduli_pa), "default youngs_modulus_pa")
    default_scale = _scale(config.get("scale", 1.0), "scale")
    per_object = config.get("objects") or {}
    if not isinstance(per_object, dict):
        raise SourceError("moduli YAML: 'objects' must be a mapping of mesh name -> settings")
    known = {p.stem for p in meshes} | {p.name for p in meshes}
    unknown = set(per_object) - known
    if unknown:
        raise SourceError(f"moduli YAML names meshes that are not in {folder}: {sorted(unknown)}")
    out = []
    for path in meshes:
        entry = per_object.get(path.name, per_object.get(path.stem, {}))
        if not isinstance(entry, dict):
            entry = {"youngs_modulus_pa": entry}
        moduli = check_moduli(entry.get("youngs_modulus_pa", default_moduli), f"{path.name}: youngs_modulus_pa")
        scale = _scale(entry.get("scale", default_scale), f"{path.name}: scale")
        try:
            shape = sim_objects.shape_from_mesh_file(path, path.stem, scale)
        except ValueError as exc:
            raise SourceError(str(exc)) from None
        out.append(EvalObject(path.stem, "user", shape, moduli, str(path.resolve()), scale))
    names = [o.name for o in out]
    if len(set(names)) != len(names):
        raise SourceError(f"{folder}: two meshes share a name (stem): {sorted(names)}")
    return out


def _scale(value, what) -> float:
    try:
        s = float(value)
    except (TypeError, ValueError):
        raise SourceError(f"{what} must be a number, got {value!r}") from None
    if not s > 0:
        raise SourceError(f"{what} must be > 0, got {s}")
    return s


def _read_yaml(path, required: bool) -> dict:
    path = Path(path)
    if not path.is_file():
        if required:
            raise SourceError(f"moduli YAML {path} does not exist")
        return {}
    try:
        data = yaml.safe_load(path.read_text(encoding="utf-8")) or {}
    except yaml.YAMLError as exc:
        raise SourceError(f"{path}: not valid YAML: {exc}") from None
    if not isinstance(data, dict):
        raise SourceError(f"{path}: expected a mapping at the top level")
    extra = set(data) - {"youngs_modulus_pa", "scale", "objects"}
    if extra:
        raise SourceError(f"{path}: unknown keys {sorted(extra)} (known: youngs_modulus_pa, scale, objects)")
    return data


def shape_from_ref(ref: tuple):
    """ObjectShape from EvalObject.ref (library object or user mesh file)."""
    set_name, name, mesh_path, scale = ref
    if mesh_path:
        return sim_objects.shape_from_mesh_file(mesh_path, name, scale)
    shape = sim_objects.get_shape(name)
    if shape.set_name != set_name:
        raise SourceError(f"object {name!r} is in set {shape.set_name!r}, not {set_name!r}")
    return shape
