"""Node set files and the commands built from them (pure, no processes)."""
import sys

import pytest

from defgg_ros.bringup.node_set import NodeSetError, load_node_set, node_command


def test_shipped_sets():
    sim = load_node_set("sim_cell")
    real = load_node_set("real_cell")
    assert sim.use_sim_time and not real.use_sim_time
    assert [n.name for n in sim.nodes] == ["fake_panda_driver", "segmentation_node", "grasp_inference_node",
                                           "executor_node"]
    assert {n.name for n in real.nodes} == {"segmentation_node", "grasp_inference_node", "executor_node"}


def test_command_passes_params_files_sim_time_and_overrides():
    entry = load_node_set("sim_cell").nodes[0]
    cmd = node_command(entry, True, {"scene_file": "x.yaml", "gui": False, "place_position_m": [0.1, 0.2]})
    assert cmd[0] == sys.executable and "--ros-args" in cmd
    assert cmd[cmd.index("--params-file") + 1].endswith("fake_panda_driver.yaml")
    params = [cmd[i + 1] for i, a in enumerate(cmd) if a == "-p"]
    assert "use_sim_time:=true" in params and 'scene_file:="x.yaml"' in params and "gui:=false" in params
    assert "place_position_m:=[0.1, 0.2]" in params


@pytest.mark.ros
def test_string_overrides_reach_a_real_node_as_the_strings_they_are(rclpy_context):
    """`-p base_frame:=` (empty), a value with ': ' or one that reads as a number: rcl refused to parse the first two
    ("Couldn't parse parameter override rule", the node died at start-up) and typed the third an integer."""
    from rclpy.node import Node

    entry = load_node_set("sim_cell").nodes[0]
    values = {"empty": "", "colon": "fer_link0: left", "digits": "42", "hash": "a # b", "names": ["x", "1"]}
    cmd = node_command(entry, False, values)
    args = cmd[cmd.index("--ros-args"):]
    args = [a for i, a in enumerate(args) if not (a == "--params-file" or (i and args[i - 1] == "--params-file"))]
    node = Node("override_probe", context=rclpy_context, cli_args=args,
                automatically_declare_parameters_from_overrides=True)
    try:
        assert {name: node.get_parameter(name).value for name in values} == values
    finally:
        node.destroy_node()


@pytest.mark.parametrize("body, words", [
    ("nodes: []", "non-empty"),
    ("nodes: [{name: a}]", "module"),
    ("nodes: [{name: a, module: m, ready: {socket: /x}}]", "ready"),
    ("nodes: [{name: a, module: m, ready: {service: x}}]", "absolute"),
    ("nodes: [{name: a, module: m, params: [missing.yaml], ready: {service: /x}}]", "does not exist"),
    ("nodes: [{name: a, module: m, ready: {service: /x}}, {name: a, module: m, ready: {service: /y}}]", "unique"),
])
def test_bad_sets_are_explained(tmp_path, body, words):
    path = tmp_path / "set.yaml"
    path.write_text(body)
    with pytest.raises(NodeSetError, match=words):
        load_node_set(str(path))


def test_unknown_set_name():
    with pytest.raises(NodeSetError, match="does not exist"):
        load_node_set("no_such_set")


def test_overrides_are_checked_against_the_node_schemas_and_typed_before_any_process_starts(tmp_path):
    from defgg_ros.bringup.cli import checked_overrides, parse_args, parse_overrides

    sim = load_node_set("sim_cell")
    out = checked_overrides(sim, parse_overrides(parse_args(["-p", "fake_panda_driver:max_real_time_factor:=0"])))
    value = out["fake_panda_driver"]["max_real_time_factor"]
    assert value == 0.0 and isinstance(value, float)        # rclpy refuses an int for a double parameter
    for argv, says in ((["-p", "grasp_inference_node:nosuch:=3"], "grasp_inference_node has no parameter 'nosuch'"),
                       (["-p", "fake_panda_driver:max_real_time_factor:=-1"], "max_real_time_factor = -1.0 must be"),
                       (["-p", "nobody:x:=1"], "node 'nobody' is not in node set 'sim_cell'"),
                       (["--scene", str(tmp_path / "none.yaml")], "--scene: scene file")):
        with pytest.raises(NodeSetError, match=says.replace("(", r"\(").replace(")", r"\)")):
            checked_overrides(sim, parse_overrides(parse_args(argv)))
    with pytest.raises(NodeSetError, match="not in node set 'real_cell'"):
        checked_overrides(load_node_set("real_cell"), parse_overrides(parse_args(["--gui"])))


def test_the_bringups_recorder_keeps_its_exit_code_and_records_the_scene_the_driver_runs(tmp_path):
    import subprocess

    from defgg_ros.bringup.cli import checked_overrides, parse_args, parse_overrides, record_hook
    from defgg_ros.ros.share import demo_scene_file

    sim = load_node_set("sim_cell")
    argv = record_hook(str(tmp_path / "bag"), sim, {})["recorder"]
    assert argv[-2:] == ["--scene", str(demo_scene_file())]     # the driver's '' scene_file is the demo scene
    other = str(demo_scene_file().with_name("rigid_box.yaml"))
    chosen = checked_overrides(sim, parse_overrides(parse_args(["--scene", other])))
    assert record_hook(str(tmp_path / "bag"), sim, chosen)["recorder"][-2:] == ["--scene", other]
    assert "--scene" not in record_hook(str(tmp_path / "bag"), load_node_set("real_cell"), {})["recorder"]
    # the recorder's own exit code comes out of the process (a bad option: 2, before anything connects)
    done = subprocess.run(argv + ["--top-k", "0"], capture_output=True, text=True, timeout=120)
    assert done.returncode == 2 and "--top-k must be >= 1" in done.stderr, done.stderr
