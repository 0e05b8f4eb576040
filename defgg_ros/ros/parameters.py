"""One parameter schema per node: declare, describe and validate a node's parameters from its YAML file.

The schema files (defgg_ros/ros/params/<node>.yaml) are written in generate_parameter_library's
format, so on a colcon build the same files can feed `generate_parameter_module`; in the pip venv
this module reads them instead:

    <node_name>:
      <parameter>:
        type: double              # bool, int, double, string, or <one of those>_array
        default_value: 0.5        # the single source of the default
        description: "..."
        read_only: true           # optional (default false): only read at start-up
        validation:               # optional; the subset of generate_parameter_library's validators below
          gt<>: [0.0]
          lt_eq<>: [1.0]

Validators: bounds<> [lo, hi] (inclusive), gt<>, gt_eq<>, lt<>, lt_eq<> [value] (arrays: every element),
one_of<> [[values]], fixed_size<> [n], size_gt<> [n], not_empty<> [].

`declare_parameters(node, schema)` declares every parameter (type, description, read-only flag and,
for bounds<>, the descriptor's range so `ros2 param describe` shows it), checks the start-up values
and refuses a bad one with ParameterError naming the parameter and its bounds (a ValueError, so
`run_node` turns it into one line and exit code 2); later `set_parameters` calls are checked against
the same rules and refused with the same message.
"""
import functools
import math
from dataclasses import dataclass, field
from pathlib import Path

import yaml

SCHEMA_DIR = Path(__file__).resolve().parent / "params"
SCALAR_TYPES = {"bool": bool, "int": int, "double": float, "string": str}
VALIDATORS = ("bounds<>", "gt<>", "gt_eq<>", "lt<>", "lt_eq<>", "one_of<>", "fixed_size<>", "size_gt<>",
              "not_empty<>")


class ParameterError(ValueError):
    """A parameter value outside its schema (the message names the parameter and the rule)."""


class SchemaError(ValueError):
    """A schema file that is not a valid schema (a bug in the repository, not a user error)."""


@dataclass(frozen=True)
class ParameterSpec:
    name: str
    type: str                       # bool, int, double, string or <scalar>_array
    default: object
    description: str
    read_only: bool = False
    validation: dict = field(default_factory=dict)

    @property
    def element_type(self) -> type:
        return SCALAR_TYPES[self.type.removesuffix("_array")]

    @property
    def is_array(self) -> bool:
        return self.type.endswith("_array")

    def rule_text(self) -> str:
        """The validation rules in words, e.g. '> 0.0 and <= 1.0' or 'one of ['a', 'b']'."""
        return " and ".join(_rule_text(kind, args) for kind, args in self.validation.items()) or f"a {self.type}"


def schema_path(node_name: str) -> Path:
    return SCHEMA_DIR / f"{node_name}.yaml"


@functools.cache
def load_schema(node_name: str) -> dict:
    """{parameter name: ParameterSpec} of defgg_ros/ros/params/<node_name>.yaml, in file order."""
    path = schema_path(node_name)
    document = yaml.safe_load(path.read_text())
    if not isinstance(document, dict) or list(document) != [node_name]:
        raise SchemaError(f"{path}: the top level must be the single key '{node_name}'")
    specs = {}
    for name, entry in document[node_name].items():
        spec = _spec_from_entry(path, name, entry)
        problem = check_value(spec, spec.default)
        if problem:
            raise SchemaError(f"{path}: the default of {problem}")
        specs[name] = spec
    return specs


def defaults(node_name: str) -> dict:
    """{parameter name: default value} of a node's schema."""
    return {name: spec.default for name, spec in load_schema(node_name).items()}


def at_default(specs: dict, name: str, value) -> bool:
    """Whether a parameter's value is its schema default (specs: load_schema's result); arrays element-wise."""
    default = specs[name].default
    if isinstance(default, (list, tuple)):
        return isinstance(value, (list, tuple)) and list(value) == list(default)
    return value == default


def _spec_from_entry(path: Path, name: str, entry) -> ParameterSpec:
    if not isinstance(entry, dict) or not {"type", "default_value", "description"} <= set(entry):
        raise SchemaError(f"{path}: {name} needs type, default_value and description")
    kind = entry["type"]
    if kind.removesuffix("_array") not in SCALAR_TYPES:
        raise SchemaError(f"{path}: {name} has unknown type {kind!r}")
    validation = dict(entry.get("validation") or {})
    unknown = set(validation) - set(VALIDATORS)
    if unknown:
        raise SchemaError(f"{path}: {name} uses validators this loader does not know: {sorted(unknown)}")
    spec = ParameterSpec(name, kind, None, str(entry["description"]), bool(entry.get("read_only", False)),
                         validation)
    return ParameterSpec(name, kind, coerce_value(spec, entry["default_value"]), spec.description, spec.read_only,
                         validation)


def coerce_value(spec: ParameterSpec, value):
    """YAML and ROS write 1 for 1.0; a double parameter holds a float (rclpy types parameters by value)."""
    if spec.element_type is float:
        if spec.is_array:
            return [float(v) if isinstance(v, int) and not isinstance(v, bool) else v for v in value]
        if isinstance(value, int) and not isinstance(value, bool):
            return float(value)
    return list(value) if spec.is_array else value


def check_value(spec: ParameterSpec, value) -> str | None:
    """None if `value` satisfies the spec, else '<name> = <value> must be <rule>'."""
    bad = f"{spec.name} = {value!r} must be "
    elements = list(value) if spec.is_array and isinstance(value, list | tuple) else None
    if spec.is_array and elements is None:
        return bad + f"a list ({spec.type})"
    for element in elements if spec.is_array else [value]:
        if not _has_type(element, spec.element_type):
            return bad + f"a {spec.type}"
    for kind, args in spec.validation.items():
        if not _passes(kind, args, value, elements):
            return bad + spec.rule_text()  # all of the rules: the bounds on both sides
    return None


def _has_type(value, wanted: type) -> bool:
    if wanted is float:
        return isinstance(value, float | int) and not isinstance(value, bool)
    if wanted is int:
        return isinstance(value, int) and not isinstance(value, bool)
    return isinstance(value, wanted)


_COMPARE = {"gt<>": lambda v, b: v > b, "gt_eq<>": lambda v, b: v >= b, "lt<>": lambda v, b: v < b,
            "lt_eq<>": lambda v, b: v <= b}


def _passes(kind: str, args, value, elements) -> bool:
    numbers = elements if elements is not None else [value]
    if kind in _COMPARE:
        return all(_finite(v) and _COMPARE[kind](v, args[0]) for v in numbers)
    if kind == "bounds<>":
        return all(_finite(v) and args[0] <= v <= args[1] for v in numbers)
    if kind == "one_of<>":
        return value in args[0]
    if kind == "fixed_size<>":
        return len(value) == args[0]
    if kind == "size_gt<>":
        return len(value) > args[0]
    if kind == "not_empty<>":
        return len(value) > 0
    raise SchemaError(f"unknown validator {kind}")


def _finite(value) -> bool:
    return isinstance(value, int) or math.isfinite(value)


def _rule_text(kind: str, args) -> str:
    return {"gt<>": lambda: f"> {args[0]}", "gt_eq<>": lambda: f">= {args[0]}", "lt<>": lambda: f"< {args[0]}",
            "lt_eq<>": lambda: f"<= {args[0]}", "bounds<>": lambda: f"in [{args[0]}, {args[1]}]",
            "one_of<>": lambda: f"one of {args[0]}", "fixed_size<>": lambda: f"exactly {args[0]} values",
            "size_gt<>": lambda: f"more than {args[0]} values", "not_empty<>": lambda: "not empty"}[kind]()


def declare_parameters(node, schema: str | None = None) -> dict:
    """Declare every parameter of `schema` (default: the node's name) on `node`, refuse bad start-up
    values (ParameterError naming the parameter and its rule), keep later changes within the schema,
    and return {name: start-up value}."""
    from rcl_interfaces.msg import SetParametersResult

    specs = load_schema(schema or node.get_name())
    for spec in specs.values():
        _declare(node, spec)
    values = {name: node.get_parameter(name).value for name in specs}
    for name, spec in specs.items():
        problem = check_value(spec, values[name])
        if problem:
            raise ParameterError(f"parameter {problem}")

    def on_set(parameters):
        for parameter in parameters:
            spec = specs.get(parameter.name)
            problem = check_value(spec, parameter.value) if spec else None
            if problem:
                return SetParametersResult(successful=False, reason=f"parameter {problem}")
        return SetParametersResult(successful=True)

    node.add_on_set_parameters_callback(on_set)
    return values


def _declare(node, spec: ParameterSpec) -> None:
    from rclpy.exceptions import InvalidParameterTypeException, InvalidParameterValueException

    try:
        node.declare_parameter(spec.name, spec.default, _descriptor(spec))
    except (InvalidParameterValueException, InvalidParameterTypeException) as error:
        # rclpy refuses a value outside the descriptor's range or of another type while declaring.
        raise ParameterError(f"parameter {spec.name} must be {spec.rule_text()} ({spec.type}): {error}") from None


def _descriptor(spec: ParameterSpec):
    from rcl_interfaces.msg import FloatingPointRange, IntegerRange, ParameterDescriptor, ParameterType

    kinds = {"bool": ParameterType.PARAMETER_BOOL, "int": ParameterType.PARAMETER_INTEGER,
             "double": ParameterType.PARAMETER_DOUBLE, "string": ParameterType.PARAMETER_STRING,
             "bool_array": ParameterType.PARAMETER_BOOL_ARRAY, "int_array": ParameterType.PARAMETER_INTEGER_ARRAY,
             "double_array": ParameterType.PARAMETER_DOUBLE_ARRAY,
             "string_array": ParameterType.PARAMETER_STRING_ARRAY}
    descriptor = ParameterDescriptor(name=spec.name, type=kinds[spec.type], description=spec.description,
                                     read_only=spec.read_only)
    if spec.validation:
        descriptor.additional_constraints = spec.rule_text()
    bounds = spec.validation.get("bounds<>")
    if bounds is not None and not spec.is_array:
        if spec.type == "double":
            descriptor.floating_point_range = [FloatingPointRange(from_value=float(bounds[0]),
                                                                  to_value=float(bounds[1]), step=0.0)]
        elif spec.type == "int":
            descriptor.integer_range = [IntegerRange(from_value=int(bounds[0]), to_value=int(bounds[1]), step=1)]
    return descriptor
