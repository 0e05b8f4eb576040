"""One parameter schema per node (defgg_ros/ros/params/*.yaml): the single source of defaults, the
shipped configs hold overrides only, and a bad value is refused with the parameter's name and bounds."""
import dataclasses
from pathlib import Path

import pytest
import yaml

from defgg_ros.bringup.shared_parameters import node_sections
from defgg_ros.ros import topics
from defgg_ros.ros.parameters import ParameterError, ParameterSpec, at_default, check_value, defaults, load_schema

ROOT = Path(__file__).resolve().parents[2]
NODES = ("executor_node", "grasp_inference_node", "segmentation_node", "fake_panda_driver")
NODE_MODULES = {"executor_node": "defgg_ros.nodes.executor_node",
                "grasp_inference_node": "defgg_ros.nodes.grasp_inference_node",
                "segmentation_node": "defgg_ros.nodes.segmentation_node",
                "fake_panda_driver": "defgg_ros.nodes.fake_panda_driver_node"}


@pytest.mark.unit
@pytest.mark.parametrize("node", NODES)
def test_every_schema_loads_with_typed_described_defaults(node):
    specs = load_schema(node)
    assert specs
    for spec in specs.values():
        assert spec.description and check_value(spec, spec.default) is None, spec
        # generate_parameter_library reads these keys; names are start-up only.
        if spec.name.endswith(("_topic", "_service", "_action")) or spec.name == "action_name":
            assert spec.read_only, spec.name


@pytest.mark.unit
@pytest.mark.parametrize("node", NODES)
def test_shipped_configs_hold_only_valid_overrides(node):
    raw = yaml.safe_load((ROOT / "sim_bringup" / "config" / f"{node}.yaml").read_text())
    assert list(raw) == [f"/**/{node}"], "keyed for any namespace (real_cell.launch.py namespace:=)"
    overrides = node_sections(raw)[node]
    specs = load_schema(node)
    assert set(overrides) <= set(specs)
    for name, value in overrides.items():
        assert value != specs[name].default, f"{name}: repeats the schema default"
        assert check_value(specs[name], value) is None


@pytest.mark.unit
@pytest.mark.parametrize("path", sorted((ROOT / "sim_bringup" / "config" / "real_cell").glob("*.yaml")),
                         ids=lambda p: p.name)
def test_robot_files_hold_only_valid_overrides(path):
    raw = yaml.safe_load(path.read_text())
    assert all(key.startswith("/**/") for key in raw), "keyed for any namespace (real_cell.launch.py namespace:=)"
    for node, section in node_sections(raw).items():
        specs = load_schema(node)
        for name, value in section.items():
            assert name in specs, f"{path.name}: {node} has no parameter {name}"
            assert not at_default(specs, name, value), f"{path.name}: {node}.{name} repeats the schema default"
            assert check_value(specs[name], value) is None


@pytest.mark.unit
def test_node_set_overrides_are_overrides():
    from defgg_ros.bringup.node_set import load_node_set

    for path in sorted((ROOT / "sim_bringup" / "config").glob("*.yaml")):
        if "nodes" not in (yaml.safe_load(path.read_text()) or {}):
            continue
        for entry in load_node_set(str(path)).nodes:
            specs = load_schema(entry.name)
            for name, value in entry.overrides.items():
                assert name in specs and not at_default(specs, name, value), f"{path.name}: {entry.name}.{name}"


@pytest.mark.unit
def test_schema_defaults_agree_with_the_code_constants_they_mirror():
    from defgg_ros.constants import PREGRASP_HEIGHT_M
    from defgg_ros.control.sequence_types import SequenceConfig
    from defgg_ros.control.trajectories import LIMITS_SAFETY_SCALE, SAMPLE_DT_S
    from defgg_ros.perception.segmentation import OBJECT_MAX_HEIGHT_M, OBJECT_MIN_HEIGHT_M
    from defgg_ros.perception.stiffness_segmenter import DEFAULT_YOUNGS_MODULUS_PA
    from defgg_ros.perception.sync import DEFAULT_CACHE_SIZE

    executor = defaults("executor_node")
    config = SequenceConfig()
    for field in dataclasses.fields(SequenceConfig):
        # Fields the node builds from other parameters (use_transfer_via, recover_after_failure, the drop zone's
        # [0, 0] = near the observation pose) are skipped.
        if field.name in executor and field.name not in ("transfer_via_position_m", "observation_q_rad",
                                                         "recovery_drop_xy_m"):
            assert executor[field.name] == getattr(config, field.name), field.name
    assert executor["limits_scale"] == LIMITS_SAFETY_SCALE and executor["trajectory_sample_dt_s"] == SAMPLE_DT_S
    assert executor["pregrasp_height_m"] == PREGRASP_HEIGHT_M
    assert executor["grasp_height_rule"] == config.grasp_height_rule
    inference, segmentation = defaults("grasp_inference_node"), defaults("segmentation_node")
    assert segmentation["default_youngs_modulus_pa"] == DEFAULT_YOUNGS_MODULUS_PA
    assert segmentation["min_object_height_m"] == OBJECT_MIN_HEIGHT_M
    assert segmentation["max_object_height_m"] == OBJECT_MAX_HEIGHT_M
    assert inference["sync_cache_size"] == DEFAULT_CACHE_SIZE


@pytest.mark.unit
@pytest.mark.parametrize("node", NODES)
def test_name_defaults_are_the_topics_module(node):
    names = {value for key, value in vars(topics).items() if key.isupper()}
    for spec in load_schema(node).values():
        if spec.name.endswith(("_topic", "_service", "_action", "_frame")) or spec.name == "action_name":
            if spec.name in ("capture_background_service",):
                continue  # the segmentation node's own service, not a cell interface
            assert spec.default in names, f"{node}.{spec.name} = {spec.default!r} is not in defgg_ros/ros/topics.py"


@pytest.mark.unit
def test_rules_name_the_parameter_and_its_bounds():
    spec = ParameterSpec("limits_scale", "double", 0.5, "d", validation={"gt<>": [0.0], "lt_eq<>": [1.0]})
    assert check_value(spec, 1.0) is None and check_value(spec, 1) is None
    assert check_value(spec, 1.5) == "limits_scale = 1.5 must be > 0.0 and <= 1.0"
    assert check_value(spec, 0.0) == "limits_scale = 0.0 must be > 0.0 and <= 1.0"
    assert "must be > 0.0" in check_value(spec, float("nan"))
    assert "a double" in check_value(spec, "fast") and "a double" in check_value(spec, True)
    rule = ParameterSpec("rule", "string", "a", "d", validation={"one_of<>": [["a", "b"]]})
    assert check_value(rule, "c") == "rule = 'c' must be one of ['a', 'b']"
    xyz = ParameterSpec("xyz", "double_array", [0.0] * 3, "d",
                        validation={"fixed_size<>": [3], "bounds<>": [-1.0, 1.0]})
    assert check_value(xyz, [0.0, 1.0]) == "xyz = [0.0, 1.0] must be exactly 3 values and in [-1.0, 1.0]"
    assert check_value(xyz, [0.0, 0.0, 2.0]) == "xyz = [0.0, 0.0, 2.0] must be exactly 3 values and in [-1.0, 1.0]"
    assert "a list" in check_value(xyz, 0.5)


@pytest.mark.ros
def test_a_bad_start_up_value_is_refused_with_name_and_bounds_and_runtime_changes_are_checked(rclpy_context):
    from rclpy.node import Node
    from rclpy.parameter import Parameter

    from defgg_ros.ros.parameters import declare_parameters

    def make(**overrides):
        node = Node("executor_node", context=rclpy_context, parameter_overrides=[
            Parameter(name, value=value) for name, value in overrides.items()])
        try:
            return node, declare_parameters(node)
        except ParameterError:
            node.destroy_node()
            raise

    with pytest.raises(ParameterError, match=r"limits_scale = 1\.5 must be > 0\.0 and <= 1\.0"):
        make(limits_scale=1.5)
    with pytest.raises(ParameterError, match=r"grasp_height_rule = 'middle' must be one of"):
        make(grasp_height_rule="middle")
    with pytest.raises(ParameterError, match="place_position_m.*exactly 3 values"):
        make(place_position_m=[0.1, 0.2])
    node, values = make(server_wait_s=1.0)
    try:
        assert values["server_wait_s"] == 1.0 and values["line_speed_mps"] == defaults("executor_node")[
            "line_speed_mps"]
        refused = node.set_parameters([Parameter("line_speed_mps", value=-0.1)])[0]
        assert not refused.successful and "line_speed_mps = -0.1 must be > 0.0" in refused.reason
        assert node.set_parameters([Parameter("line_speed_mps", value=0.2)])[0].successful
        assert not node.set_parameters([Parameter("joint_states_topic", value="/other")])[0].successful  # read-only
    finally:
        node.destroy_node()


@pytest.mark.ros
def test_bounds_go_into_the_descriptor_and_an_out_of_range_value_names_them(rclpy_context):
    from rclpy.node import Node
    from rclpy.parameter import Parameter

    from defgg_ros.ros.parameters import declare_parameters

    node = Node("fake_panda_driver", context=rclpy_context)
    try:
        declare_parameters(node)
        descriptor = node.describe_parameter("depth_dropout_fraction")
        assert descriptor.read_only
        (range_,) = descriptor.floating_point_range
        assert (range_.from_value, range_.to_value) == (0.0, 1.0)
    finally:
        node.destroy_node()
    node = Node("fake_panda_driver", context=rclpy_context,
                parameter_overrides=[Parameter("depth_dropout_fraction", value=1.5)])
    try:
        with pytest.raises(ParameterError, match=r"depth_dropout_fraction must be in \[0\.0, 1\.0\]"):
            declare_parameters(node)
    finally:
        node.destroy_node()
