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
    assert "use_sim_time:=true" in params and "scene_file:=x.yaml" in params and "gui:=false" in params
    assert "place_position_m:=[0.1, 0.2]" in params


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
