"""The trial protocol as one value (sim/protocol.py) and a trial's settings in their stored form
(sim/trial_settings.py): what the generator, the evaluation, the cards and the checkpoints carry, and the one
conversion that reads every stored settings dict back (old datasets and evaluation folders load and resume)."""
import json
from dataclasses import replace
from pathlib import Path

import pytest

from defgg_ros.sim.protocol import DEFGRASPSIM, LEGACY, PROTOCOLS, TrialProtocol, resolve_protocol
from defgg_ros.sim.trial_settings import RECORD_FIELDS, TrialSettings

pytestmark = pytest.mark.unit

DATASETS = Path(__file__).resolve().parents[2] / "datasets"


def generator_header(name: str) -> dict:
    return json.loads((DATASETS / name / "dataset.json").read_text())["generator"]


@pytest.mark.parametrize("name, protocol, lift_time_s, confident_min_directions", [
    ("fem_v1", LEGACY, 0.3, 4), ("fem_v2", LEGACY, 0.6, 4), ("fem_v4", LEGACY, 0.6, 3),
    ("fem_v5", DEFGRASPSIM, 0.6, 3)])
def test_every_shipped_dataset_header_reads_back_as_the_settings_its_trials_ran(name, protocol, lift_time_s,
                                                                                 confident_min_directions):
    settings = TrialSettings.from_generator_header(generator_header(name))
    assert settings.protocol == PROTOCOLS[protocol]
    assert settings.motion.lift_time_s == lift_time_s
    assert settings.generator.confident_min_directions == confident_min_directions


def test_the_stored_form_is_the_flat_dict_records_have_always_had():
    stored = generator_header("fem_v5")["trial_settings"]
    settings = TrialSettings.from_record(stored)
    assert settings.to_record() == {**stored, "shake_stop_when_decided": False}   # the one field it predates
    assert tuple(settings.to_record()) == RECORD_FIELDS and len(RECORD_FIELDS) == 27
    assert TrialSettings.from_record(settings.to_record()) == settings


def test_a_protocol_is_one_value_that_the_trial_asks():
    legacy, defgraspsim = PROTOCOLS[LEGACY], PROTOCOLS[DEFGRASPSIM]
    assert legacy.test_gravity_mps2()[2] < 0 and not defgraspsim.test_gravity_mps2().any()
    assert legacy.finger_force_n(2e5, 0.05) == 2.5                       # 2 N + 0.5 N per decade
    assert defgraspsim.finger_force_n(2e5, 0.05) == pytest.approx((1 + 5.30103 / 10) * 0.05 * 9.81 / 0.7 / 2,
                                                                  rel=1e-4)
    one_finger = [3, 0]
    assert legacy.held(one_finger, lambda: 0.01) and not legacy.held(one_finger, lambda: 0.03)
    assert not defgraspsim.held(one_finger, lambda: 0.0)
    assert replace(defgraspsim, finger_hold="lock").locks_fingers(True)
    assert not replace(defgraspsim, finger_hold="lock").locks_fingers(False)      # the rigid stand-in
    assert not replace(legacy, finger_hold="lock").locks_fingers(True)            # legacy force-holds


def test_a_stored_protocol_setting_converts_both_ways():
    for protocol in PROTOCOLS.values():
        assert TrialProtocol.from_setting(protocol.to_setting()) == protocol
    pilot_b = TrialProtocol.from_setting({"protocol": "defgraspsim", "object_friction": 0.4,
                                          "grip_force_friction": 0.7})
    assert pilot_b.material.effective_friction == pytest.approx(0.4) and pilot_b.grip_force_mu() == 0.7
    assert pilot_b.label_grip_rule().to_meta() == {"protocol": "defgraspsim", "friction": 0.7}
    assert TrialProtocol.from_setting({}) == PROTOCOLS[LEGACY]         # a record without a name predates it
    with pytest.raises(ValueError, match="unknown trial protocol"):
        TrialProtocol.from_setting({"protocol": "isaac"})


def test_one_resolver_the_datasets_setting_then_the_request_then_the_folders_then_the_default():
    pilot = {"protocol": "defgraspsim", "object_friction": 0.4}
    assert resolve_protocol("legacy", {"protocol": "legacy"}, pilot).material.object_friction == 0.4
    assert resolve_protocol("legacy", {"protocol": "defgraspsim"}).name == LEGACY
    assert resolve_protocol(None, {"lift_time_s": 0.6}).name == LEGACY            # a record without a protocol
    assert resolve_protocol() == PROTOCOLS[DEFGRASPSIM]


def test_the_finger_drive_is_stored_only_when_it_is_not_the_speed_drive_every_older_setting_ran():
    stored = generator_header("fem_v5")["trial_settings"]
    speed = TrialSettings.from_record(stored)
    assert speed.protocol.finger_drive == "speed" and "finger_drive" not in speed.to_record()
    press = speed.with_fields(finger_drive="press")
    assert press.to_record() == {**speed.to_record(), "finger_drive": "press"}
    assert TrialSettings.from_record(press.to_record()) == press
    assert press.protocol.summary().startswith("**defgraspsim**") and "pressing hand" in press.protocol.summary()
    assert speed.protocol.summary().startswith("**defgraspsim**") and "pressing" not in speed.protocol.summary()
    assert PROTOCOLS[LEGACY].summary().startswith("**legacy**")
    from defgg_ros.sim.trial_settings import comparable_protocol
    assert comparable_protocol(press.to_record()) != comparable_protocol(speed.to_record())
    with pytest.raises(ValueError, match="finger_drive must be one of speed, press"):
        speed.with_fields(finger_drive="torque")


def test_an_evaluation_from_a_pressed_dataset_presses_too():
    """defgg-eval run --protocol-from DATASET reads the header's trial settings: the drive comes along."""
    from defgg_ros.evaluation.runner import eval_trial_settings

    pressed = TrialSettings.fast().with_fields(finger_drive="press").to_record()
    assert eval_trial_settings(resolve_protocol(dataset_setting=pressed)).protocol.finger_drive == "press"
    assert eval_trial_settings(resolve_protocol()).protocol.finger_drive == "speed"
