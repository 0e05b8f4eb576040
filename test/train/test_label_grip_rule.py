"""The weights record the grip force rule of their labels (read from the dataset header), so the cell can
close a grasp with the force its quality assumes (grip_force.LabelGripRule, planning/grip_estimate.py)."""
import json
import shutil

import pytest
import torch

from defgg_ros.data.header import label_grip_rule
from defgg_ros.grip_force import LabelGripRule
from defgg_ros.model.checkpoint import load_checkpoint
from defgg_ros.train.cli import main

ARGS = ["--epochs", "1", "--batch-size", "2", "--samples-per-scene", "1", "--seed", "5", "--no-progress",
        "--val-fraction", "0.3", "--test-fraction", "0.3", "--max-steps", "2"]


def test_a_header_names_its_labels_rule():
    assert label_grip_rule({}) == label_grip_rule("synthetic") == {"protocol": "legacy", "friction": None}
    assert label_grip_rule({"trial_settings": {"protocol": "legacy"}})["protocol"] == "legacy"
    default = label_grip_rule({"trial_settings": {"protocol": "defgraspsim", "grip_force_friction": None}})
    assert default == {"protocol": "defgraspsim", "friction": pytest.approx(0.7)}    # the contact's (0.7 x 1.0)
    own = label_grip_rule({"trial_settings": {"protocol": "defgraspsim", "grip_force_friction": 0.5,
                                              "object_friction": 0.4}})
    assert own["friction"] == 0.5                                   # the rule's own mu, not the contact's
    contact = label_grip_rule({"trial_settings": {"protocol": "defgraspsim", "object_friction": 0.4}})
    assert contact["friction"] == pytest.approx(0.4)


@pytest.mark.parametrize("protocol", ["legacy", "defgraspsim"])
def test_trained_weights_carry_the_rule_and_the_trial_protocol_of_their_labels(tiny_dataset, tmp_path, protocol,
                                                                              capsys):
    torch.set_num_threads(1)
    data = tmp_path / "data"
    shutil.copytree(tiny_dataset, data)
    header_path = data / "dataset.json"
    header = json.loads(header_path.read_text())
    header["generator"] = {"trial_settings": {"protocol": protocol}}
    header_path.write_text(json.dumps(header))
    assert main(["--data", str(data), "--out", str(tmp_path / "run"), *ARGS]) == 0
    meta = load_checkpoint(tmp_path / "run" / "model.pt")["meta"]
    rule = LabelGripRule.from_meta(meta)
    assert rule.protocol == protocol and rule.needs_mass == (protocol == "defgraspsim")
    assert meta["label_grip_rule"] == label_grip_rule(header["generator"])
    assert meta["trial_protocol"] == {"protocol": protocol, "object_friction": None, "poisson_ratio": None,
                                      "finger_hold": "force", "grip_force_friction": None}
    out = capsys.readouterr().out
    assert f"labels of the trial protocol **{protocol}** (" in out              # printed when training starts
    assert json.loads(out[out.index("{"):])["trial_protocol"]["protocol"] == protocol   # and in the summary
