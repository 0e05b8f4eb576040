"""A recorded message as the installed rclpy type, also after the interface gained fields.

A session sends some recorded messages back into the live graph (SetStiffness assignments, PlanGrasp
requests, PickAndPlace goals). Their CDR bytes only fit the definition they were recorded with: a goal
recorded before Grasp gained estimated_mass_kg and finger_force_n does not deserialize as today's goal.
So a message recorded with our own interfaces is decoded with the bag's definition (BagMessage.decode)
and copied field by field into the installed type; fields added since keep their defaults (0: "not
known"), fields removed since are dropped.
"""
from __future__ import annotations

import importlib

import numpy as np
from rclpy.serialization import deserialize_message


def live_message(recorded, cls):
    """The BagMessage `recorded` as an instance of the rclpy message class `cls`."""
    if not recorded.msgdef:
        return deserialize_message(recorded.raw, cls)
    return copy_fields(recorded.decode(), cls())


def copy_fields(source, target):
    """Copy the fields `target` (an rclpy message) shares by name with `source` (any object with those
    attributes, e.g. a rosbags dataclass), recursively; returns target."""
    for name, type_name in target.get_fields_and_field_types().items():
        if not hasattr(source, name):
            continue
        value = getattr(source, name)
        current = getattr(target, name)
        if hasattr(current, "get_fields_and_field_types"):
            copy_fields(value, current)
        elif "/" in type_name:                       # a sequence or array of messages
            element = _message_class(type_name[type_name.index("<") + 1:].split(",")[0].rstrip(">")
                                     if "<" in type_name else type_name.split("[")[0])
            setattr(target, name, [copy_fields(v, element()) for v in value])
        elif isinstance(value, np.ndarray):
            setattr(target, name, value.tobytes() if value.dtype == np.uint8 else value.tolist())
        else:
            setattr(target, name, value)
    return target


def _message_class(type_name: str):
    """'pkg/Name' or 'pkg/msg/Name' -> the rclpy class."""
    parts = type_name.split("/")
    return getattr(importlib.import_module(f"{parts[0]}.msg"), parts[-1])
