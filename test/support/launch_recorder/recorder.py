"""Evaluate a LaunchDescription of the stand-in classes: the environment it sets and the nodes it starts."""
from dataclasses import dataclass, field

import yaml
from launch.actions import DeclareLaunchArgument, SetEnvironmentVariable
from launch.substitutions import perform_all
from launch_ros.actions import Node


@dataclass
class Context:
    launch_configurations: dict
    package_shares: dict


@dataclass
class StartedNode:
    package: str
    executable: str
    name: str
    namespace: str
    parameter_files: list          # paths, in the order given
    parameter_values: dict         # the dicts' entries, later entries win (as in ROS)
    parameter_order: list = field(default_factory=list)   # ("file", path) | ("dict", {...}) in order


@dataclass
class Evaluated:
    arguments: dict
    environment: dict
    nodes: list


def _is_substitution(value) -> bool:
    return hasattr(value, "perform") or (isinstance(value, (list, tuple)) and value
                                         and all(isinstance(v, str) or hasattr(v, "perform") for v in value)
                                         and any(hasattr(v, "perform") for v in value))


def _parameter_value(value, context):
    # launch_ros performs a substitution and reads the text as YAML ('60.0' -> 60.0, 'true' -> True)
    if _is_substitution(value):
        return yaml.safe_load(perform_all(value, context))
    return value


def _node(node: Node, context: Context) -> StartedNode:
    files, values, order = [], {}, []
    for item in node.parameters:
        if isinstance(item, dict):
            resolved = {key: _parameter_value(value, context) for key, value in item.items()}
            values.update(resolved)
            order.append(("dict", resolved))
        else:
            path = perform_all(item, context)
            files.append(path)
            order.append(("file", path))
    namespace = perform_all(node.namespace, context) if node.namespace is not None else ""
    return StartedNode(node.package, perform_all(node.executable, context), perform_all(node.name, context),
                       namespace, files, values, order)


def evaluate(description, arguments: dict, package_shares: dict) -> Evaluated:
    context = Context(dict(arguments), dict(package_shares))
    environment, nodes, declared = {}, [], set()
    for entity in description.entities:
        if isinstance(entity, DeclareLaunchArgument):
            declared.add(entity.name)
            if entity.name not in context.launch_configurations:
                if entity.default_value is None:
                    raise ValueError(f"required launch argument {entity.name!r} not given")
                context.launch_configurations[entity.name] = perform_all(entity.default_value, context)
            value = context.launch_configurations[entity.name]
            if entity.choices is not None and value not in entity.choices:
                raise ValueError(f"argument {entity.name!r}: {value!r} is not one of {entity.choices}")
        elif isinstance(entity, SetEnvironmentVariable):
            environment[perform_all(entity.name, context)] = perform_all(entity.value, context)
        elif isinstance(entity, Node):
            nodes.append(_node(entity, context))
        else:
            raise TypeError(f"the recorder does not know {type(entity).__name__}")
    unknown = set(arguments) - declared
    if unknown:
        raise ValueError(f"arguments the launch file does not declare: {sorted(unknown)}")
    return Evaluated(context.launch_configurations, environment, nodes)
