"""defgg_ros/sim/trimesh_import.py: trimesh keeps a KeyboardInterrupt that lands during its optional imports
(its `except BaseException`); the check finds it, and only it, in trimesh's real ExceptionWrapper."""
import types

import pytest
from trimesh.exceptions import ExceptionWrapper

from defgg_ros.sim.trimesh_import import swallowed_interrupt, trimesh

pytestmark = pytest.mark.unit


def _module_holding(exception):
    module = types.ModuleType("trimesh_fake_optional")
    module.networkx = ExceptionWrapper(exception)
    return module


def test_a_kept_keyboard_interrupt_is_found():
    assert swallowed_interrupt([_module_holding(KeyboardInterrupt())])


def test_a_missing_optional_dependency_is_not_an_interrupt():
    assert not swallowed_interrupt([_module_holding(ImportError("no module named networkx"))])


def test_the_trimesh_this_process_imported_kept_none():
    assert isinstance(trimesh.Trimesh, type)
    assert not swallowed_interrupt()
