"""The bringup refuses a cell whose nodes would start with different table, frame, camera or arm values
(pure: node set files, parameter files and -p overrides; no processes)."""
import re
import shlex
from pathlib import Path

import pytest

from defgg_ros.bringup.cli import check_cell_parameters_agree, checked_overrides, parse_args, parse_overrides
from defgg_ros.bringup.node_set import NodeSetError, load_node_set
from defgg_ros.bringup.shared_parameters import disagreements

DOCS = Path(__file__).resolve().parents[2] / "docs" / "real_cell.md"


def _overrides(set_name, argv):
    return checked_overrides(load_node_set(set_name), parse_overrides(parse_args(argv)))


@pytest.mark.parametrize("set_name", ["sim_cell", "real_cell", "real_cell_fer"])
def test_the_shipped_sets_agree(set_name):
    assert disagreements(load_node_set(set_name)) == []


def test_one_node_with_another_table_height_is_refused_naming_every_node():
    overrides = _overrides("real_cell", ["-p", "executor_node:table_z_m:=0.02"])
    with pytest.raises(NodeSetError, match="table_z_m") as err:
        check_cell_parameters_agree(load_node_set("real_cell"), overrides)
    text = str(err.value)
    assert "executor_node=0.02" in text and "segmentation_node=0.0" in text
    # the same height for both starts (the inference node has no table: it plans on the perceived one)
    argv = [a for node in ("executor_node", "segmentation_node")
            for a in ("-p", f"{node}:table_z_m:=0.02")]
    check_cell_parameters_agree(load_node_set("real_cell"), _overrides("real_cell", argv))


def test_a_grasp_height_rule_set_for_the_executor_alone_is_refused():
    overrides = _overrides("sim_cell", ["-p", "executor_node:grasp_height_rule:=below_surface"])
    with pytest.raises(NodeSetError, match="grasp_height_rule") as err:
        check_cell_parameters_agree(load_node_set("sim_cell"), overrides)
    assert "executor_node='below_surface'" in str(err.value) and "grasp_inference_node=" in str(err.value)


def test_a_workspace_box_set_for_one_node_alone_is_refused():
    """The executor's recovery drops a held object inside its box; a box perception does not share would leave it
    where no grasp is planned."""
    overrides = _overrides("real_cell", ["-p", "segmentation_node:workspace_box_m:=[0.3, 0.8, -0.3, 0.3]"])
    with pytest.raises(NodeSetError, match="workspace_box_m") as err:
        check_cell_parameters_agree(load_node_set("real_cell"), overrides)
    assert "executor_node=" in str(err.value) and "segmentation_node=" in str(err.value)


def _fr3_rehearsal_argv():
    text = DOCS.read_text()
    block = re.search(r"```bash\n(defgg-bringup --ros-domain 42 -p fake_panda_driver:robot_type:=fr3.*?)```", text,
                      re.S)
    assert block, "the FR3 rehearsal command is no longer in docs/real_cell.md"
    return shlex.split(block.group(1).replace("\\\n", " "))[1:]


def test_the_documented_fr3_rehearsal_agrees_and_without_the_drivers_arm_it_would_not():
    argv = _fr3_rehearsal_argv()
    check_cell_parameters_agree(load_node_set("sim_cell"), _overrides("sim_cell", argv))
    i = argv.index("fake_panda_driver:robot_type:=fr3")
    lines = disagreements(load_node_set("sim_cell"), _overrides("sim_cell", argv[:i - 1] + argv[i + 1:]))
    assert lines == ["robot_type: fake_panda_driver='fer', executor_node='fr3'",
                     "base_frame: fake_panda_driver='fer_link0', segmentation_node='fr3_link0', "
                     "executor_node='fr3_link0'"]


def test_parameter_files_count_with_their_wildcard_section(tmp_path):
    config = Path(load_node_set("real_cell").config_dir)
    shared = tmp_path / "cell.yaml"
    shared.write_text("/**:\n  ros__parameters:\n    table_z_m: 0.01\n")
    one = tmp_path / "one.yaml"
    one.write_text("segmentation_node:\n  ros__parameters:\n    table_z_m: 0.03\n")

    def node_set(files):
        path = tmp_path / "set.yaml"
        nodes = [f"  - {{name: {n}, module: m, params: [{config / (n + '.yaml')}{files}], "
                 f"ready: {{service: /x{i}}}}}" for i, n in enumerate(("segmentation_node", "executor_node"))]
        path.write_text("nodes:\n" + "\n".join(nodes) + "\n")
        return load_node_set(str(path))

    assert disagreements(node_set(f", {shared}")) == []
    assert disagreements(node_set(f", {shared}, {one}")) == [
        "table_z_m: segmentation_node=0.03, executor_node=0.01"]
