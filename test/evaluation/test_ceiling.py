"""The candidate ceiling: sampler candidates under the task, random-pick and best-case rates."""
import json

import pytest

from defgg_ros.atomic import read_jsonl
from defgg_ros.evaluation import ceiling
from defgg_ros.evaluation.cli import main as eval_main


def _rec(obj, e, success, task="shake"):
    return {"object": obj, "youngs_modulus_pa": e, "task": task, "success": success}


def test_summary_separates_random_pick_from_ceiling():
    records = [_rec("a", 2e4, True), _rec("a", 2e4, False), _rec("a", 2e4, False), _rec("a", 2e4, False),
               _rec("b", 2e4, False), _rec("b", 2e4, False),
               _rec("a", 2e9, True), _rec("b", 2e9, True), _rec("b", 2e9, None)]   # None: sim failure, not counted
    rows = {r["youngs_modulus_pa"]: r for r in ceiling.summarize(records)}
    assert rows[2e4]["random_pct"] == pytest.approx(12.5)      # mean of 1/4 and 0/2
    assert rows[2e4]["ceiling_pct"] == pytest.approx(50.0)      # a has a success, b none
    assert rows[2e9]["trials"] == 2 and rows[2e9]["ceiling_pct"] == 100.0
    assert rows["all"]["objects"] == 4 and rows["all"]["random_pct"] == pytest.approx((25 + 0 + 100 + 100) / 4)


def test_plan_rejects_bad_input():
    with pytest.raises(ValueError, match="candidates per object"):
        ceiling.plan_trials([], [2e9], 0, "shake", 0)
    with pytest.raises(ValueError, match="unknown task"):
        ceiling.plan_trials([], [2e9], 1, "juggle", 0)


def test_ceiling_command_runs_real_trials_and_resumes(tmp_path, capsys):
    out = tmp_path / "ceil"
    argv = ["ceiling", "--out", str(out), "--only", "common_sponge", "--moduli", "2e9", "--candidates", "2"]
    assert eval_main(argv) == 0
    lines = [json.loads(x) for x in (out / ceiling.RESULTS_FILE).read_text().splitlines()]
    assert [r["candidate"] for r in lines] == [0, 1]
    for r in lines:
        assert r["status"] in ("ok", "lift_failed") and r["cpu_s"] > 0
        assert r["trial_settings"]["protocol"] == "defgraspsim"       # the default: the label's own rule
        ok = r["status"] == "ok"
        assert r["success"] == (ok and sum(r["accels"]) / 16 >= 25.0 * (1 - 1e-6))
        assert r["success_every_direction"] == (ok and min(r["accels"]) >= 25.0 * (1 - 1e-6))
    table = (out / ceiling.TABLE_FILE).read_text()
    assert "| shake | 2e+09 | 1 | 2 |" in table and "common_sponge" in table
    capsys.readouterr()
    assert eval_main(argv) == 0                      # rerun: nothing left to simulate
    assert len((out / ceiling.RESULTS_FILE).read_text().splitlines()) == 2
    assert "[1/" not in capsys.readouterr().out
    (command,) = ceiling.recorded_commands(out)          # once, though it ran twice
    assert command.startswith("defgg-eval ceiling --out") and "--candidates 2" in command


def test_stiffness_advantage_is_per_modulus_choice_minus_one_choice():
    def rec(obj, c, e, ok):
        return {"object": obj, "candidate": c, "youngs_modulus_pa": e, "task": "shake", "success": ok}

    # object a: candidate 0 holds only when soft, candidate 1 only when rigid -> stiffness helps
    # object b: candidate 0 holds at both moduli -> nothing to gain; candidate 2 ran at one modulus only
    records = [rec("a", 0, 2e4, True), rec("a", 0, 2e9, False), rec("a", 1, 2e4, False), rec("a", 1, 2e9, True),
               rec("b", 0, 2e4, True), rec("b", 0, 2e9, True), rec("b", 1, 2e4, False), rec("b", 1, 2e9, False),
               rec("b", 2, 2e4, True)]
    (row,) = ceiling.stiffness_advantage(records)
    assert row["views"] == 4
    assert row["one_for_all_pct"] == pytest.approx(75.0)      # a: 1 of 2, b: 2 of 2
    assert row["per_modulus_pct"] == pytest.approx(100.0)


def test_ceiling_refuses_a_folder_of_another_protocol(tmp_path, capsys):

    from defgg_ros.evaluation.runner import eval_trial_settings
    from defgg_ros.sim.objects import get_shape

    trials = ceiling.plan_trials([get_shape("common_sponge")], [2e9], 1, "shake", 0)
    ceiling.run(tmp_path, trials, "shake", eval_trial_settings().with_fields(lift_time_s=0.3))
    with pytest.raises(ValueError, match="another protocol"):
        ceiling.run(tmp_path, trials, "shake", eval_trial_settings())


def test_executor_height_ceiling_runs_comparable_grasps_in_its_own_folder(tmp_path):
    """--grasp-height executor: the candidates sit at the evaluation's grasp height, their keys differ
    from the contacts rule's, and a folder of one rule refuses trials of the other."""
    from defgg_ros.evaluation.runner import eval_trial_settings
    from defgg_ros.grasping.geometry import tcp_height_m
    from defgg_ros.sim.objects import get_shape
    from defgg_ros.sim.sampler import _surface_height_m

    shape = get_shape("common_sponge")
    executor = ceiling.plan_trials([shape], [2e9], 1, "shake", 0, grasp_height="executor")
    contacts = ceiling.plan_trials([shape], [2e9], 1, "shake", 0)
    (key, _, _, _, grasp), = executor
    assert key.endswith("|height=executor") and key != contacts[0][0]
    top_z = _surface_height_m(grasp.position_m, shape.surface().triangles)
    assert grasp.position_m[2] == pytest.approx(tcp_height_m(top_z), abs=1e-3)
    assert ceiling.run(tmp_path, executor, "shake", eval_trial_settings(), grasp_height="executor") == 1
    assert read_jsonl(tmp_path / ceiling.RESULTS_FILE)[0]["grasp_height"] == "executor"
    with pytest.raises(ValueError, match="new --out folder"):
        ceiling.run(tmp_path, contacts, "shake", eval_trial_settings())
