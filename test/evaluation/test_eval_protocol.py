"""The evaluation's trial protocol: a twist the simulated hand survives, and one protocol per task and folder."""
import json
import math

import pytest

from defgg_ros.evaluation import cli
from defgg_ros.evaluation.runner import eval_trial_settings
from defgg_ros.sim import objects
from defgg_ros.sim.trial import WorldGrasp, run_grasp_trial
from defgg_ros.sim.trial_settings import task_protocol

CENTRED = WorldGrasp((0.0, 0.0, 0.02), math.pi / 2, 0.03)     # across the 3 cm side of box_small


def test_a_firm_rigid_grasp_holds_the_twist_about_every_axis():
    """Real PyBullet: with the one-way twist of before 2026-11-25 this grasp was "lost" at 185-415 rad/s^2
    (the hand itself came apart at ~25 rad/s of spin; bench/bench_twist_limit.py)."""
    settings = eval_trial_settings().with_fields(twist_fail_below_radps2=None)
    out = run_grasp_trial(objects.ObjectSpec(objects.get_shape("box_small"), 2e9), CENTRED, ("twist",), settings)
    assert out.status == "ok", out.note
    assert out.twist_accels_radps2 == [500.0] * 6 and all(out.twist_measured)


def _folder(tmp_path, records):
    with (tmp_path / "trials.jsonl").open("w") as f:
        for r in records:
            f.write(json.dumps(r) + "\n")
    return tmp_path


def _settings(**changes) -> dict:
    return eval_trial_settings().with_fields(**changes).to_record()


def test_task_protocol_drops_only_the_other_tasks_settings():
    slow_twist = _settings(twist_oscillation_radps=None)
    assert task_protocol(slow_twist, "shake") == task_protocol(_settings(), "shake")
    assert task_protocol(slow_twist, "twist") != task_protocol(_settings(), "twist")
    assert task_protocol(_settings(lift_time_s=0.3), "twist") != task_protocol(_settings(), "twist")
    with pytest.raises(KeyError):
        task_protocol(_settings(), "squeeze")


def test_a_new_twist_ramp_keeps_the_folders_shake_trials_but_refuses_its_old_twist_trials(tmp_path):
    one_way = {k: v for k, v in _settings().items() if k != "twist_oscillation_radps"}   # recorded before it existed
    out = _folder(tmp_path, [{"key": "a", "task": "shake", "trial_settings": one_way},
                             {"key": "b", "task": "twist", "trial_settings": one_way}])
    cli.check_same_protocol(out, eval_trial_settings(), ["shake"])                 # accepted
    with pytest.raises(ValueError, match="twist trials of another protocol .*twist_oscillation_radps"):
        cli.check_same_protocol(out, eval_trial_settings(), ["shake", "twist"])


def test_a_shared_setting_refuses_every_task(tmp_path):
    out = _folder(tmp_path, [{"key": "a", "task": "shake", "trial_settings": _settings(lift_time_s=0.3)}])
    with pytest.raises(ValueError, match="shake trials of another protocol .*lift_time_s"):
        cli.check_same_protocol(out, eval_trial_settings(), ["shake"])
    cli.check_same_protocol(out, eval_trial_settings(), ["twist"])     # no twist trial there to mix with


def test_the_twist_limit_bench_reruns_a_recorded_trial(tmp_path):
    """bench/bench_twist_limit.py on one recorded rigid twist trial (the can of results/sim_v4, one-way twist;
    the grasp at full precision: a 1e-7 change of it moves the held value by a ramp step)."""
    import subprocess
    import sys
    from pathlib import Path

    record = {"key": "k", "task": "twist", "experiment": "main", "rank": 0, "model": "m", "object": "common_can",
              "object_set": "common", "youngs_modulus_pa": 2e9, "part_moduli_pa": [2e9],
              "object_yaw_rad": 0.5242208014656741,
              "grasp": {"position_m": [-0.017507142339433943, -0.0018428570883614675, 0.04525001049041749],
                        "yaw_rad": 0.27020367980003357, "width_m": 0.04324560849507959},
              "trial_settings": _settings(twist_oscillation_radps=None, protocol="legacy"),
              "accels": [225.0, 0, 0, 0, 0, 0]}
    results = _folder(tmp_path, [record]) / "trials.jsonl"
    bench = Path(__file__).resolve().parents[2] / "bench" / "bench_twist_limit.py"
    done = subprocess.run([sys.executable, str(bench), str(results), "--variants", "as_eval", "osc_40"],
                          capture_output=True, text=True, timeout=300)
    assert done.returncode == 0, done.stderr[-3000:]
    assert "first axis reproduces the record in 1/1" in done.stdout, done.stdout
    assert "osc_40: grip 4.5 N/finger, 1/1 lifted, held all axes 1/1" in done.stdout, done.stdout


def test_the_evaluation_takes_the_datasets_protocol_setting_with_its_material_and_force_rule(tmp_path):
    """defgg-eval run --protocol-from DATASET: success is judged under the labels' own setting (pilot b's here)."""
    from pathlib import Path

    source = Path(__file__).resolve().parents[2] / "bench" / "pilots" / "a_defgraspsim" / "dataset.json"
    header = json.loads(source.read_text(encoding="utf-8"))
    header["generator"]["trial_settings"].update(object_friction=0.4, grip_force_friction=0.7)
    (tmp_path / "dataset.json").write_text(json.dumps(header), encoding="utf-8")
    protocol = cli.protocol_of_run("unused", "legacy", from_dataset=str(tmp_path))   # the dataset's wins
    assert protocol.to_setting() == {"protocol": "defgraspsim", "object_friction": 0.4, "poisson_ratio": None,
                                     "finger_hold": "force", "grip_force_friction": 0.7}
    settings = eval_trial_settings(protocol)
    assert settings.protocol.material.effective_friction == 0.4 and settings.protocol.grip_force_friction == 0.7
    assert settings.with_fields(object_friction=None, grip_force_friction=None) == eval_trial_settings()
    assert cli.protocol_of_run("unused", "legacy").name == "legacy"


def test_protocol_from_a_dataset_without_recorded_trial_settings_is_refused(tmp_path):
    """Headers before 2026-11-24 do not say how their labels were made: the run must name the protocol."""
    from pathlib import Path

    source = Path(__file__).resolve().parents[2] / "bench" / "pilots" / "a_defgraspsim" / "dataset.json"
    header = json.loads(source.read_text(encoding="utf-8"))
    del header["generator"]["trial_settings"]
    (tmp_path / "dataset.json").write_text(json.dumps(header), encoding="utf-8")
    with pytest.raises(ValueError, match="records no trial settings"):
        cli.protocol_of_run("unused", None, from_dataset=str(tmp_path))


def test_protocol_from_a_folder_that_is_no_dataset_is_one_clear_line(tmp_path, capsys):
    assert cli.main(["run", "--out", str(tmp_path / "out"), "--protocol-from", str(tmp_path / "nothing"),
                     "--plan-only", "--no-progress"]) == 2
    err = capsys.readouterr().err
    assert err.startswith("defgg-eval: error:") and "not a defgg dataset" in err and "Traceback" not in err


@pytest.mark.parametrize("option, value", [("--grasps", "0"), ("--workers", "0"), ("--ranks", "0"),
                                           ("--max-trials", "-1"), ("--report-every", "0")])
def test_count_options_out_of_range_are_refused_before_anything_runs(tmp_path, capsys, option, value):
    assert cli.main(["run", "--out", str(tmp_path / "out"), option, value, "--plan-only", "--no-progress"]) == 2
    assert f"defgg-eval: error: {option} must be >= " in capsys.readouterr().err
    assert not (tmp_path / "out").exists()


@pytest.mark.parametrize("folder, protocol", [("sim_v5", "defgraspsim"), ("sim_v4", "legacy")])
def test_the_stored_settings_of_a_shipped_evaluation_are_read_back_and_resume_it(folder, protocol):
    """results/sim_v5's records hold exactly today's evaluation settings in their stored form (so its trial keys,
    jobs.sim_key, are today's); sim_v4's predate shake_stop_when_decided and still compare as the same protocol."""
    from pathlib import Path

    from defgg_ros.evaluation.store import read_results, results_path

    root = Path(__file__).resolve().parents[2] / "results" / folder
    first = read_results(results_path(root))[0]
    assert cli.protocol_of_run(root, None).name == protocol
    settings = eval_trial_settings(protocol)
    if folder == "sim_v5":
        assert first["trial_settings"] == settings.to_record()
    assert task_protocol(first["trial_settings"], first["task"]) == task_protocol(settings.to_record(), first["task"])


def test_a_second_run_into_a_folder_being_written_is_refused_and_writes_nothing(tmp_path, capsys):
    """Two runs appending to one folder (a restart while the first still runs, a --plan-only beside a run) wrote
    each trial twice and cut the other's unfinished last line; the folder then could not be resumed."""
    from defgg_ros.atomic import only_writer

    out = tmp_path / "out"
    out.mkdir()
    argv = ["run", "--out", str(out), "--sets", "common", "--only", "common_sponge", "--moduli", "2e9", "--grasps",
            "1", "--experiments", "main", "--quick", "--no-progress", "--plan-only"]
    with only_writer(out / ".eval.lock", RuntimeError("held by the first run")):
        assert cli.main(argv) == 2
        assert "is being written by another defgg-eval run" in capsys.readouterr().err
        assert sorted(p.name for p in out.iterdir()) == [".eval.lock"]
    assert cli.main(argv) == 0          # the first run gone: the folder is free again
    assert (out / "run.json").exists()
