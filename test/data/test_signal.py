"""The signal report on hand-made trial records whose figures can be worked out by hand."""
import gzip
import json

import pytest

from defgg_ros.data import datagen_cli
from defgg_ros.data.signal import (
    SignalError,
    read_trial_records,
    render_markdown,
    signal_report,
    spearman,
    what_labels_carry,
)

pytestmark = pytest.mark.unit


def rec(obj, cand, e, held, status="ok", force=1.0, mass=0.1):
    return {"object_name": obj, "candidate_index": cand, "youngs_modulus_pa": e, "scene_id": f"{obj}__{e:.0e}",
            "status": status, "shake_accels_mps2": None if status != "ok" else [held] * 4,
            "grasp_force_n": force, "sim": {"mass_kg": mass, "settings": {"protocol": "defgraspsim"}}}


def reversal_records():
    """Two objects x two candidates x (2e4, 2e9). Object A: candidate 0 is the soft grasp (held at 2e4 only),
    candidate 1 the stiff one (held at 2e9 only): a stiffness-aware choice is right at both, a blind one
    at one of two. Object B: candidate 0 always holds."""
    out = []
    for e, c0, c1 in ((2e4, 30.0, 10.0), (2e9, 10.0, 40.0)):
        out += [rec("A", 0, e, c0), rec("A", 1, e, c1)]
    for e in (2e4, 2e9):
        out += [rec("B", 0, e, 45.0), rec("B", 1, e, 0.0, status="lift_failed")]
    return out


def test_oracle_gap_and_reversals_of_a_pinch_versus_cage_object():
    r = signal_report(reversal_records())
    assert r["oracle"]["best"]["aware"] == 1.0
    assert r["oracle"]["best"]["blind"] == 0.75          # A: 1 of 2 moduli, B: both
    assert r["oracle"]["best"]["gap_points"] == pytest.approx(25.0)
    c = r["candidates"]
    assert c["n"] == 4
    assert c["softest_pos_rigid_neg_count"] == 1 and c["soft_neg_rigid_pos"] == 0.25
    assert c["monotone"] == 0.75
    assert r["positive_rate"]["2e4"]["rate"] == 0.5 and r["positive_rate"]["2e9"]["rate"] == 0.5
    # Where the gap lives: all of it on A (aware 2 of 2, blind 1 of 2: 50 points), none on B.
    per_object = r["oracle"]["per_object"]
    assert per_object["A"]["best_gap_points"] == pytest.approx(50.0)
    assert per_object["B"]["best_gap_points"] == 0.0 and per_object["B"]["candidates"] == 2
    assert "ahead (points, best / best 5): A 50.0 / " in render_markdown(r)
    assert "level on the other 1 object(s)" in render_markdown(r)


def test_what_labels_carry_follows_the_gap_the_within_share_and_the_near_threshold_share():
    pinch_or_cage = what_labels_carry(signal_report(reversal_records()))
    assert pinch_or_cage[1].startswith('- Can carry "stiffness changes which grasp is good"'), pinch_or_cage
    assert "25.0 points" in pinch_or_cage[1] and not any(line.startswith("- Noisy") for line in pinch_or_cage)
    # the same candidates hold at every modulus, every hold near 25 m/s^2: no gap, noisy labels
    same_everywhere = [rec(o, i, e, 24.0 + i) for o in "AB" for i in range(3) for e in (2e4, 2e9)]
    lines = what_labels_carry(signal_report(same_everywhere))
    assert lines[1].startswith('- Cannot carry') and "0.0 points" in lines[1], lines
    assert lines[-1].startswith("- Noisy: 100.0 %"), lines
    assert "67 / 67 % positive" in lines[0], lines[0]


def test_within_scene_share_is_zero_when_only_the_object_matters_and_one_when_only_the_grasp_does():
    only_object = [rec("A", i, 2e4, 10.0) for i in range(3)] + [rec("B", i, 2e4, 40.0) for i in range(3)]
    only_grasp = [rec(o, i, 2e4, [0.0, 20.0, 40.0][i]) for o in "AB" for i in range(3)]
    assert signal_report(only_object)["within_scene_share"]["soft"] == 0.0
    assert signal_report(only_grasp)["within_scene_share"]["soft"] == pytest.approx(1.0)


def test_near_threshold_share_counts_held_accelerations_within_the_band():
    # 2e4: 23.0 and 27.4 inside +-2.5 of 25, 30.0 and a lift failure (0) outside; 2e9: 22.6 inside, 45 outside.
    records = [rec("A", 0, 2e4, 23.0), rec("A", 1, 2e4, 27.4), rec("A", 2, 2e4, 30.0),
               rec("A", 3, 2e4, 0.0, status="lift_failed"), rec("A", 0, 2e9, 22.6), rec("A", 1, 2e9, 45.0)]
    near = signal_report(records)["near_threshold"]
    assert near["2e4"] == 0.5 and near["2e9"] == 0.5 and near["all"] == pytest.approx(0.5)


def test_spearman_with_ties():
    assert spearman([1, 2, 3, 4], [10, 20, 30, 40]) == pytest.approx(1.0)
    assert spearman([1, 2, 3, 4], [4, 3, 2, 1]) == pytest.approx(-1.0)
    assert spearman([1, 1, 2], [5, 5, 9]) == pytest.approx(1.0)


def test_cli_reads_plain_and_gzip_trials_and_writes_json_and_markdown(tmp_path, capsys):
    trials = tmp_path / "pilot" / "trials"
    trials.mkdir(parents=True)
    records = reversal_records()
    (trials / "A.jsonl").write_text("".join(json.dumps(r) + "\n" for r in records[:4]))
    with gzip.open(trials / "B.jsonl.gz", "wt") as fh:
        fh.write("".join(json.dumps(r) + "\n" for r in records[4:]))
    assert len(read_trial_records(tmp_path / "pilot")) == 8
    rc = datagen_cli.main(["signal", str(tmp_path / "pilot"), "--json", str(tmp_path / "s.json"),
                           "--md", str(tmp_path / "s.md"), "--png", str(tmp_path / "s.png")])
    assert rc == 0
    assert (tmp_path / "s.png").read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
    assert json.loads((tmp_path / "s.json").read_text())["oracle"]["best"]["gap_points"] == pytest.approx(25.0)
    assert "gap 25.0 points" in (tmp_path / "s.md").read_text() and "gap 25.0 points" in capsys.readouterr().out


def test_cli_refuses_a_folder_without_trials(tmp_path, capsys):
    assert datagen_cli.main(["signal", str(tmp_path)]) == 2
    assert "no trial files" in capsys.readouterr().err
    with pytest.raises(SignalError):
        signal_report([rec("A", 0, 2e4, 1.0, status="exploded")])


def test_shake_and_twist_rule_needs_both_and_refuses_records_without_a_twist():
    held = rec("A", 0, 2e4, 30.0)
    weak_twist = dict(held, twist_accels_radps2=[100.0] * 6)
    strong_twist = dict(held, twist_accels_radps2=[400.0] * 6)
    records = [weak_twist, dict(strong_twist, candidate_index=1)]
    r = signal_report(records, "shake_and_twist")
    assert r["label_rule"] == "shake_and_twist" and r["positive_rate"]["2e4"]["positive"] == 1
    assert signal_report(records)["positive_rate"]["2e4"]["positive"] == 2
    with pytest.raises(SignalError, match="no twist recorded"):
        signal_report([held], "shake_and_twist")


def test_card_has_no_signal_report_for_trials_without_a_shake(tmp_path):
    from defgg_ros.data.card import SIGNAL_FIGURE, write_signal_section
    from defgg_ros.data.format import FORMAT_NAME, FORMAT_VERSION

    def header(generator):
        return json.dumps({"format": FORMAT_NAME, "version": FORMAT_VERSION, "generator": generator})

    (tmp_path / "trials").mkdir()
    (tmp_path / "trials" / "A__2e+04.jsonl").write_text(json.dumps(rec("A", 0, 2e4, 30.0)) + "\n")
    (tmp_path / "dataset.json").write_text(header({"tests": ["twist"]}))
    assert "ran no shake" in "\n".join(write_signal_section(tmp_path))
    assert not (tmp_path / SIGNAL_FIGURE).exists()
    (tmp_path / "dataset.json").write_text(header({}))
    lines = "\n".join(write_signal_section(tmp_path))
    assert "Signal report" in lines and f"![signal report]({SIGNAL_FIGURE})" in lines
    assert (tmp_path / SIGNAL_FIGURE).stat().st_size > 1000


def test_the_threshold_moves_the_labels_not_the_measurements():
    """signal_report(threshold_mps2=...): the same records, another threshold (bench/analyze_threshold_gap.py)."""
    records = [rec("cube", c, e, held) for c, (e, held) in enumerate([(2e4, 21.0), (2e4, 27.0), (2e9, 21.0),
                                                                     (2e9, 27.0)])]
    at_25 = signal_report(records)
    at_20 = signal_report(records, threshold_mps2=20.0)
    assert at_25["threshold_mps2"] == 25.0 and at_20["threshold_mps2"] == 20.0
    assert at_25["positive_rate"]["2e4"]["rate"] == 0.5 and at_20["positive_rate"]["2e4"]["rate"] == 1.0
    assert at_25["within_scene_share"] == at_20["within_scene_share"]


def test_cli_takes_a_twist_only_folder_s_shake_from_another_folder(tmp_path, capsys):
    """A try that simulated only the twist (bench/pilots/d_defgraspsim_twist) is reported with the shake of the
    same trial ids from the try it shares settings with; a twist run that failed overrides the shake's status."""
    shakes = [dict(r, trial_id=f"t{i}") for i, r in enumerate(reversal_records())]
    twists = [dict(r, shake_accels_mps2=None, twist_accels_radps2=[400.0 if r["candidate_index"] == 0 else 100.0] * 6,
                   status="ok" if i != 1 else "lift_failed") for i, r in enumerate(shakes)]
    for name, records in (("shake", shakes), ("twist", twists[:-1])):   # the last twist not run yet
        (tmp_path / name / "trials").mkdir(parents=True)
        (tmp_path / name / "trials" / "all.jsonl").write_text("".join(json.dumps(r) + "\n" for r in records))
    assert datagen_cli.main(["signal", str(tmp_path / "twist"), "--label", "shake_and_twist"]) == 2   # no shake
    capsys.readouterr()
    rc = datagen_cli.main(["signal", str(tmp_path / "twist"), "--label", "shake_and_twist", "--shake-from",
                           str(tmp_path / "shake"), "--json", str(tmp_path / "s.json")])
    assert rc == 0
    report = json.loads((tmp_path / "s.json").read_text())
    assert report["trials"] == report["labelled"] == 7   # 7 twists have a shake; lift failures are negatives
    # A's soft grasp holds the shake and the twist at 2e4; its stiff one holds the shake at 2e9 but not the twist.
    assert report["positive_rate"]["2e4"]["positive"] == 2 and report["positive_rate"]["2e9"]["positive"] == 1
