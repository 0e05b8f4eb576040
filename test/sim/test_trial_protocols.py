"""The two trial protocols in real PyBullet: what each trial records is what the engine really did.

defgraspsim: zero gravity after settling, total grip force FOS*m*g/mu, the table moved away, fingers
locked on a soft object (force-held on the rigid stand-in), lost as soon as either finger lets go.
legacy: fem_v1-v4's protocol, unchanged (gravity on, 2 N + 0.5 N per decade, both-fingers/20 mm rule).
"""
import math

import pytest

from defgg_ros.data.format import STATUS_OK, TrialRecord
from defgg_ros.grip_force import grasp_force_n
from defgg_ros.sim import objects, trial, world
from defgg_ros.sim.trial import TrialSettings, WorldGrasp, run_grasp_trial
from defgg_ros.sim.trial_settings import comparable_protocol

pytestmark = pytest.mark.sim

QUICK = TrialSettings.exact().with_fields(close_settle_s=0.05, hold_time_s=0.05, lift_time_s=0.15,
                            shake_ramp_time_s=0.3, shake_directions=2, stop_when_label_decided=False)
CENTRED = WorldGrasp((0.0, 0.0, 0.02), math.pi / 2, 0.03)


def box(e):
    return objects.ObjectSpec(objects.get_shape("box_small"), e)


@pytest.mark.parametrize("finger_hold", ["force", "lock"])
def test_defgraspsim_soft_trial_records_zero_gravity_weight_force_hold_and_either_finger_rule(finger_hold):
    settings = QUICK.with_fields(protocol="defgraspsim", finger_hold=finger_hold)
    out = run_grasp_trial(box(2e4), CENTRED, ("shake",), settings)
    assert out.status == STATUS_OK, out.note
    sim = out.sim
    assert sim["protocol"] == "defgraspsim" and sim["settings"]["protocol"] == "defgraspsim"
    assert sim["gravity_during_test_mps2"] == [0.0, 0.0, 0.0]
    assert sim["effective_friction"] == pytest.approx(0.7) and sim["poisson_ratio"] == 0.3
    total = (1 + math.log10(2e4) / 10) * sim["mass_kg"] * world.GRAVITY_MPS2 / 0.7
    assert out.grasp_force_n == pytest.approx(total / 2)
    assert sim["fingers_locked"] is (finger_hold == "lock") and sim["loss_rule"] == "either_finger"
    # at 2e4 Pa the soft body's compression keeps most of the squeeze even under the lock
    assert all(f > 0.5 * out.grasp_force_n for f in sim["squeeze_after_pickup_n"]), sim["squeeze_after_pickup_n"]


def test_grip_force_friction_squeezes_as_if_the_contact_were_grippier():
    """Pilot b: the object's friction 0.4, the force rule's mu 0.7: friction alone holds FOS*g*0.4/0.7."""
    settings = QUICK.with_fields(protocol="defgraspsim", object_friction=0.4, grip_force_friction=0.7)
    out = run_grasp_trial(box(2e5), CENTRED, ("shake",), settings)
    assert out.status == STATUS_OK, out.note
    assert out.sim["effective_friction"] == pytest.approx(0.4)
    total = (1 + math.log10(2e5) / 10) * out.sim["mass_kg"] * world.GRAVITY_MPS2 / 0.7
    assert out.grasp_force_n == pytest.approx(total / 2)
    own_friction = settings.with_fields(grip_force_friction=None)
    by_own_friction = run_grasp_trial(box(2e5), CENTRED, ("shake",), own_friction)
    assert by_own_friction.grasp_force_n == pytest.approx(out.grasp_force_n * 0.7 / 0.4)


def test_defgraspsim_rigid_stand_in_is_force_held_not_locked():
    out = run_grasp_trial(box(2e9), CENTRED, ("shake",), QUICK.with_fields(protocol="defgraspsim"))
    assert out.status == STATUS_OK, out.note
    assert out.sim["fingers_locked"] is False and out.sim["gravity_during_test_mps2"] == [0.0, 0.0, 0.0]
    assert out.sim["squeeze_after_pickup_n"] == pytest.approx([out.grasp_force_n] * 2, rel=0.05)


def test_legacy_trial_records_gravity_fixed_force_and_the_old_loss_rule():
    out = run_grasp_trial(box(2e5), CENTRED, ("shake",), QUICK.with_fields(protocol="legacy"))
    assert out.status == STATUS_OK, out.note
    sim = out.sim
    assert sim["gravity_during_test_mps2"] == pytest.approx([0.0, 0.0, -world.GRAVITY_MPS2])
    assert out.grasp_force_n == pytest.approx(grasp_force_n(2e5)) == pytest.approx(2.5)
    assert sim["effective_friction"] == pytest.approx(0.64) and sim["poisson_ratio"] is None
    assert sim["fingers_locked"] is False and sim["loss_rule"] == "both_fingers_or_20mm"


@pytest.mark.parametrize("protocol, held_with_one_finger", [("defgraspsim", False), ("legacy", True)])
def test_one_finger_off_the_object_is_lost_only_under_the_either_finger_rule(client, protocol, held_with_one_finger):
    import pybullet as p

    run = trial._Trial(client, box(2e9), CENTRED, QUICK.with_fields(protocol=protocol), (0, 0), 0.0)
    run.grasp_and_lift()
    assert run.held()
    if run.hand.gear_id is not None:      # free the second finger from the first
        p.removeConstraint(run.hand.gear_id, physicsClientId=client)
    finger = run.hand.FINGER_LINKS[1]
    p.resetJointState(run.hand.body_id, finger, 0.04, 0.0, physicsClientId=client)
    p.setJointMotorControl2(run.hand.body_id, finger, p.POSITION_CONTROL, targetPosition=0.04, force=50.0,
                            physicsClientId=client)
    run.world.step()
    per_finger = [sum(c) for c in zip(*[run.hand.finger_contacts(b) for b in run.obj.body_ids])]
    assert per_finger[0] > 0 and per_finger[1] == 0, per_finger
    assert run.held() is held_with_one_finger


def test_protocol_and_material_are_validated():
    with pytest.raises(ValueError, match="unknown trial protocol"):
        TrialSettings().with_fields(protocol="isaac")
    with pytest.raises(ValueError, match="object_friction"):
        TrialSettings().with_fields(object_friction=0.0)
    with pytest.raises(ValueError, match="grip_force_friction"):
        TrialSettings().with_fields(grip_force_friction=-0.7)
    with pytest.raises(ValueError, match="finger_hold"):
        TrialSettings().with_fields(finger_hold="glue")
    with pytest.raises(ValueError, match="unknown trial settings"):
        TrialSettings().with_fields(lift_time=0.6)
    settings = TrialSettings().with_fields(protocol="defgraspsim", object_friction=0.4)
    assert settings.protocol.material.effective_friction == 0.4


def test_records_without_a_protocol_compare_as_legacy():
    recorded = TrialSettings.legacy().to_record()
    for key in ("protocol", "object_friction", "poisson_ratio", "grip_force_friction"):
        recorded.pop(key)
    assert comparable_protocol(recorded) == comparable_protocol(TrialSettings.legacy().to_record())
    assert comparable_protocol(recorded) != comparable_protocol(TrialSettings.fast().to_record())


@pytest.mark.parametrize("dataset, trial_id", [
    ("fem_v4", "pyramid__E2e+04__g037"), ("fem_v4", "egad_train_06_c4__E2e+09__g000"),
    ("fem_v4", "ycb_banana__E2e+04__g014"), ("fem_v5", "cube__E2e+09__g000"), ("fem_v5", "capsule__E2e+09__g010"),
    ("fem_v5p", "ycb_banana__E2e+04__g005")])
def test_stored_trials_of_both_protocols_replay_exactly(dataset, trial_id):
    """A soft positive, rigid trials and a lift failure of datasets/fem_v4 (legacy protocol, its records predate
    the protocol fields), rigid trials of fem_v5 (defgraspsim) and a soft trial of fem_v5p pressed by the trial
    hand (a negative of fem_v5 that holds pressing), rerun from their records: every field the record stores comes
    out the same but the CPU time."""
    from pathlib import Path

    from defgg_ros.data.datagen import job_from_record, run_trial_job
    from defgg_ros.data.format import read_trials

    root = Path(__file__).resolve().parents[2] / "datasets" / dataset
    stored = next(t for t in read_trials(root, trial_id.rsplit("__", 1)[0]) if t.trial_id == trial_id).to_json()
    rerun = run_trial_job(job_from_record(TrialRecord.from_json(stored)))
    assert rerun["sim"]["settings"] == TrialSettings.from_record(stored["sim"]["settings"]).to_record()
    for record in (stored, rerun):
        record.pop("cpu_s")
        record["sim"].pop("settings")
    rerun["sim"] = {k: rerun["sim"][k] for k in stored["sim"]}     # fem_v4 predates the protocol facts
    assert rerun == stored


@pytest.mark.unit
def test_twist_stop_fills_the_remaining_axes_only_once_the_label_is_certain():
    from defgg_ros.constants import TWIST_ACCEL_LIMIT_RADPS2, TWIST_POSITIVE_THRESHOLD_RADPS2
    from defgg_ros.sim.trial import TWIST_AXES, label_decided_fill

    def twist_label_decided(values):
        return label_decided_fill(values, len(TWIST_AXES), TWIST_POSITIVE_THRESHOLD_RADPS2, TWIST_ACCEL_LIMIT_RADPS2)

    assert twist_label_decided([500.0, 500.0, 500.0]) == 0.0                # 1500 reached: positive whatever follows
    assert twist_label_decided([500.0, 500.0, 400.0]) is None               # 1400 + up to 1500 more: open
    assert twist_label_decided([0.0, 0.0, 0.0, 490.0]) == 500.0             # 490 + 1000 < 1500: negative
    assert twist_label_decided([0.0, 0.0, 0.0, 500.0]) is None              # 500 + 1000 = 1500: could still pass
    assert twist_label_decided([100.0] * 6) is None                         # nothing left to fill


def test_the_evaluations_shake_stops_once_both_outcomes_are_certain_and_neither_changes(client):
    """shake_stop_when_decided: a weak grip (force rule's mu 2.0 on a 0.7 contact) on the rigid box fails
    directions early; once the mean cannot reach 25 m/s^2 and a direction has failed, the rest is skipped."""
    from defgg_ros.evaluation.tasks import outcome_fields

    weak = QUICK.with_fields(protocol="defgraspsim", shake_directions=16, stop_when_label_decided=False,
                               grip_force_friction=2.0)
    full = run_grasp_trial(box(2e9), CENTRED, ("shake",), weak, client=client)
    early = run_grasp_trial(box(2e9), CENTRED, ("shake",), weak.with_fields(shake_stop_when_decided=True),
                            client=client)
    assert full.status == early.status == STATUS_OK, (full.note, early.note)
    assert all(full.shake_measured) and not all(early.shake_measured)       # the stop did happen
    assert early.sim_steps < full.sim_steps
    measured = sum(early.shake_measured)
    assert early.shake_accels_mps2[:measured] == full.shake_accels_mps2[:measured]   # the same trial up to it
    assert outcome_fields("shake", early.status, early.shake_accels_mps2, "defgraspsim") == \
        outcome_fields("shake", full.status, full.shake_accels_mps2, "defgraspsim") == \
        {"success": False, "success_every_direction": False}


def test_the_evaluations_shake_caps_a_direction_once_its_outcomes_are_certain_and_neither_changes(client):
    """shake_stop_when_decided on a grasp that holds: once the held sum reaches 25 m/s^2 * 16 the mean is
    certain, so later directions ramp only until held at 25 m/s^2 (the every-direction outcome); each capped
    value is a lower bound of the full trial's."""
    from defgg_ros.evaluation.tasks import outcome_fields

    firm = QUICK.with_fields(protocol="defgraspsim", shake_directions=16, stop_when_label_decided=False)
    full = run_grasp_trial(box(2e9), CENTRED, ("shake",), firm, client=client)
    capped = run_grasp_trial(box(2e9), CENTRED, ("shake",), firm.with_fields(shake_stop_when_decided=True),
                             client=client)
    assert full.status == capped.status == STATUS_OK, (full.note, capped.note)
    assert min(full.shake_accels_mps2) >= 25.0, full.shake_accels_mps2    # the grasp holds: nothing fails early
    assert capped.sim_steps < full.sim_steps and not all(capped.shake_measured)
    for f, c, m in zip(full.shake_accels_mps2, capped.shake_accels_mps2, capped.shake_measured):
        assert c == f if m else 25.0 <= c <= f
    assert outcome_fields("shake", capped.status, capped.shake_accels_mps2, "defgraspsim") == \
        outcome_fields("shake", full.status, full.shake_accels_mps2, "defgraspsim") == \
        {"success": True, "success_every_direction": True}
