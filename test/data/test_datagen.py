"""The generator: kill-and-restart gives the same trial set without duplicates; pass order; Ray path.

Rigid objects (E = 2e9) keep these runs to seconds; the trial machinery is
the same for soft ones (test/sim/test_trial.py).
"""
import json
import os
import signal
import subprocess
import sys
import time
from collections import Counter
from dataclasses import replace

import pytest

from defgg_ros.atomic import read_jsonl
from defgg_ros.data import datagen
from defgg_ros.data.format import DatasetWriter, list_scene_ids, read_scene, read_trials

OBJECTS = ("box_small", "cube")
QUICK = {"close_settle_s": 0.05, "lift_time_s": 0.15, "hold_time_s": 0.05, "shake_ramp_time_s": 0.3}


def _cli(out, grasps=4):
    return [sys.executable, "-m", "defgg_ros.data.datagen_cli", "--out", str(out), "--objects", *OBJECTS,
            "--moduli", "2e9", "--grasps-per-scene", str(grasps), "--pass-size", "2", "--no-progress",
            "--settings", json.dumps(QUICK)]


def _trial_ids(out):
    ids = []
    for path in sorted((out / "trials").glob("*.jsonl")):
        ids += [r["trial_id"] for r in read_jsonl(path)]
    return ids


def _wait_for_first_trial(proc, out, timeout_s=300):
    deadline = time.monotonic() + timeout_s
    while time.monotonic() < deadline:
        if _trial_ids(out) if (out / "trials").exists() else []:
            return
        if proc.poll() is not None:
            pytest.fail(f"generator ended before writing a trial: {proc.stderr.read()}")
        time.sleep(0.2)  # polling a subprocess's files; there is no event to wait on
    pytest.fail("no trial written in time")


def test_killed_and_restarted_run_has_every_trial_once(tmp_path):
    out = tmp_path / "ds"
    env = dict(os.environ)
    proc = subprocess.Popen(_cli(out), env=env, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    _wait_for_first_trial(proc, out)
    proc.send_signal(signal.SIGKILL)
    proc.wait()
    partial = _trial_ids(out)
    assert 1 <= len(partial) < 8
    done = subprocess.run(_cli(out), env=env, capture_output=True, text=True, timeout=600)
    assert done.returncode == 0, done.stderr
    ids = _trial_ids(out)
    assert not [i for i, n in Counter(ids).items() if n > 1], "duplicate trials after restart"
    expected = {f"{o}__E2e+09__g{i:03d}" for o in OBJECTS for i in range(4)}
    assert set(ids) == expected
    assert set(partial) <= set(ids)
    for sid in list_scene_ids(out):
        scene = read_scene(out / "scenes" / f"{sid}.npz")
        assert scene.depth_m.shape == (300, 300) and scene.object_mask.max() == 1
        assert all(t.label is not None for t in read_trials(out, sid))
    assert "trials finished: 8 of 8" in (out / "card.md").read_text()
    # a rerun of a finished dataset does nothing
    again = subprocess.run(_cli(out), env=env, capture_output=True, text=True, timeout=600)
    assert again.returncode == 0 and json.loads(again.stdout.strip().splitlines()[-1])["done"] == 0

    # growing the dataset adds trials pass by pass over all scenes
    cfg = datagen.DatagenConfig(out=out, objects=OBJECTS, moduli_pa=(2e9,), grasps_per_scene=8, pass_size=2,
                                settings=QUICK)
    per_scene = datagen.plan_scenes(cfg, DatasetWriter(out, cfg.header()))
    assert all(len(cands) >= 8 for _, cands, _ in per_scene.values())     # both objects have 8 to run
    jobs = datagen.pass_order(cfg, per_scene)
    assert [j.candidate_index for j in jobs] == [4, 5, 4, 5, 6, 7, 6, 7]


def test_ray_path_gives_the_local_results(tmp_path):
    pytest.importorskip("ray")
    settings = dict(QUICK)
    local_cfg = datagen.DatagenConfig(out=tmp_path / "local", objects=("cube",), moduli_pa=(2e9,),
                                      grasps_per_scene=2, pass_size=2, settings=settings)
    ray_cfg = datagen.DatagenConfig(out=tmp_path / "ray", objects=("cube",), moduli_pa=(2e9,),
                                    grasps_per_scene=2, pass_size=2, settings=settings, workers=2,
                                    ray_address="local")
    datagen.generate(local_cfg, progress_bar=False)
    counts = datagen.generate(ray_cfg, progress_bar=False)
    assert counts["done"] == 2
    sid = "cube__E2e+09"
    by_id = {t.trial_id: t for t in read_trials(tmp_path / "local", sid)}
    for t in read_trials(tmp_path / "ray", sid):
        assert t.label == by_id[t.trial_id].label
        assert t.shake_accels_mps2 == pytest.approx(by_id[t.trial_id].shake_accels_mps2, abs=0.5)


def test_coarse_fem_mesh_is_recorded_and_fixed_for_the_dataset(tmp_path):
    out = tmp_path / "coarse"
    cfg = datagen.DatagenConfig(out=out, objects=("cube",), moduli_pa=(2e5, 2e9), grasps_per_scene=1, pass_size=1,
                                settings=QUICK, sim_max_tet_nodes=datagen.COARSE_SIM_MAX_TET_NODES)
    assert datagen.generate(cfg, progress_bar=False)["done"] == 2
    (soft,) = read_trials(out, "cube__E2e+05")
    (rigid,) = read_trials(out, "cube__E2e+09")
    assert 4 <= max(soft.sim["tet_nodes"]) <= datagen.COARSE_SIM_MAX_TET_NODES
    scene = read_scene(out / "scenes" / "cube__E2e+05.npz")
    # images keep the shipped mesh, and so do rigid bodies (no speed to gain, and facets change the grip)
    assert scene.meta["tet_nodes"] == rigid.sim["tet_nodes"] != soft.sim["tet_nodes"]
    # resuming with another FEM mesh would mix discretizations: refused, the CLI says how to resume
    done = subprocess.run([sys.executable, "-m", "defgg_ros.data.datagen_cli", "--out", str(out), "--objects", "cube",
                           "--moduli", "2e5", "2e9", "--grasps-per-scene", "2", "--no-progress",
                           "--sim-max-tet-nodes", "0", "--settings", json.dumps(QUICK)],
                          capture_output=True, text=True, timeout=600)
    assert done.returncode == 2 and f"--sim-max-tet-nodes {datagen.COARSE_SIM_MAX_TET_NODES}" in done.stderr
    assert len(read_trials(out, "cube__E2e+05")) == 1


def test_grasp_height_rule_is_recorded_and_fixed_for_the_dataset(tmp_path):
    from defgg_ros.data.format import DatasetError, check_header

    out = tmp_path / "executor"
    cfg = datagen.DatagenConfig(out=out, objects=("cube",), moduli_pa=(2e9,), grasps_per_scene=1, pass_size=1,
                                settings=QUICK, grasp_height="executor")
    assert datagen.generate(cfg, progress_bar=False)["done"] == 1
    assert check_header(out)["generator"]["grasp_height"] == "executor"
    cached = json.loads((out / "candidates" / "cube.json").read_text())
    assert cached["key"]["grasp_height"] == "executor"
    with pytest.raises(DatasetError, match="--grasp-height executor"):
        datagen.generate(replace(cfg, grasp_height="contacts"), progress_bar=False)


def test_a_new_dataset_samples_at_the_executor_height_and_a_resumed_one_keeps_its_rule(tmp_path):
    assert datagen.resolve_grasp_height(tmp_path / "new", None) == "executor"
    assert datagen.resolve_grasp_height(tmp_path / "new", "contacts") == "contacts"
    legacy = tmp_path / "legacy"                     # headers before 2026-11-26 did not record the rule
    header = datagen.DatagenConfig(out=legacy).header()
    del header["grasp_height"]
    DatasetWriter(legacy, header)
    assert datagen.resolve_grasp_height(legacy, None) == "contacts"
    datagen.check_resumable(datagen.DatagenConfig(out=legacy, grasp_height="contacts"))
    executor = tmp_path / "executor"
    DatasetWriter(executor, datagen.DatagenConfig(out=executor).header())
    assert datagen.resolve_grasp_height(executor, None) == "executor"


def test_a_resume_keeps_the_seed_and_candidates_and_one_run_writes_a_folder_at_a_time(tmp_path):
    """Another --seed or --candidates resampled the pending candidates while the header kept the old ones (the
    dataset no longer reproduced from it); two runs into one folder appended every pending trial twice."""
    from defgg_ros.atomic import only_writer
    from defgg_ros.data.format import DatasetError

    out = tmp_path / "d"
    DatasetWriter(out, datagen.DatagenConfig(out=out, seed=0).header())
    for cfg, says in ((datagen.DatagenConfig(out=out, seed=1), "--seed 0"),
                      (datagen.DatagenConfig(out=out, n_candidates=50), "--candidates"),
                      (datagen.DatagenConfig(out=out, object_set="common"), "--object-set train")):
        with pytest.raises(DatasetError, match=says):
            datagen.check_resumable(cfg)
    datagen.check_resumable(datagen.DatagenConfig(out=out, seed=0))
    with only_writer(out / datagen.LOCK_FILE, RuntimeError("held")):       # a run writing the folder
        with pytest.raises(DatasetError, match="another defgg-datagen run is writing"):
            datagen.generate(datagen.DatagenConfig(out=out, objects=("cube",), moduli_pa=(2e9,)), progress_bar=False)


KNOBS_BEFORE_THEY_WERE_RECORDED = {"confident_min_directions": 4, "confident_margin_mps2": 40.0}


def test_resume_keeps_the_trial_protocol_of_the_dataset(tmp_path):
    from defgg_ros.data.format import DatasetError

    out = tmp_path / "legacy"
    cfg = datagen.DatagenConfig(out=out, objects=("cube",), moduli_pa=(2e9,))
    legacy_header = cfg.header()
    del legacy_header["trial_settings"]            # headers written before the protocol was recorded
    DatasetWriter(out, legacy_header)
    with pytest.raises(DatasetError, match='"lift_time_s": 0.3') as err:
        datagen.check_resumable(cfg)
    assert '"hold_time_s": 0.1' in str(err.value) and '"confident_margin_mps2": 40.0' in str(err.value)
    assert '"protocol": "legacy"' in str(err.value)
    datagen.check_resumable(datagen.DatagenConfig(out=out, objects=("cube",), moduli_pa=(2e9,), settings={
        "lift_time_s": 0.3, "hold_time_s": 0.1, "confident_min_directions": 4, "confident_margin_mps2": 40.0,
        "protocol": "legacy"}))
    # recorded after the lift fix, before the confident-stop knobs existed (datasets/fem_v2)
    before_knobs = tmp_path / "before_knobs"
    header = datagen.DatagenConfig(out=before_knobs).header()
    for key in ("confident_min_directions", "confident_margin_mps2"):
        del header["trial_settings"][key]
    DatasetWriter(before_knobs, header)
    with pytest.raises(DatasetError, match='"confident_min_directions": 4'):
        datagen.check_resumable(datagen.DatagenConfig(out=before_knobs))
    datagen.check_resumable(datagen.DatagenConfig(out=before_knobs, settings=KNOBS_BEFORE_THEY_WERE_RECORDED))
    # a new dataset records its whole protocol; changing one value on resume is refused
    new = tmp_path / "new"
    DatasetWriter(new, datagen.DatagenConfig(out=new, settings={"shake_ramp_time_s": 0.5}).header())
    datagen.check_resumable(datagen.DatagenConfig(out=new, settings={"shake_ramp_time_s": 0.5}))
    with pytest.raises(DatasetError, match="another trial protocol"):
        datagen.check_resumable(datagen.DatagenConfig(out=new, settings={"shake_ramp_time_s": 0.25}))


def test_card_states_the_shake_early_stop_the_dataset_was_made_with():
    from defgg_ros.data.card import _protocol_line

    header = datagen.DatagenConfig(out=None).header()
    assert "20/sqrt(k) m/s^2 from the threshold after k >= 3 directions" in _protocol_line(header)
    legacy = {k: v for k, v in header.items() if k != "trial_settings"}   # before the protocol was recorded
    assert "40/sqrt(k) m/s^2 from the threshold after k >= 4 directions" in _protocol_line(legacy)
    header["trial_settings"]["confident_stop"] = False
    assert "no early stop on the measured mean" in _protocol_line(header)


def test_card_states_the_grip_force_rule_of_the_recorded_protocol():
    from defgg_ros.data.card import _force_line

    header = datagen.DatagenConfig(out=None).header()        # the default protocol: defgraspsim
    assert "FOS * m * g / mu" in _force_line(header)
    legacy = {**{k: v for k, v in header.items() if k != "trial_settings"}, "settings": {}}   # as fem_v1-v4
    assert "0.5 N per decade" in _force_line(legacy)


def test_card_names_objects_without_candidates_and_counts_labels_per_scene():
    from defgg_ros.data.card import _coverage_lines

    rows = {("box", 2e4): {"pos": 3, "neg": 1}, ("box", 2e9): {"pos": 6, "neg": 0},
            ("cone", 2e4): {"pos": 0, "neg": 0}, ("cone", 2e9): {"pos": 0, "neg": 0}}
    lines = _coverage_lines(rows, {"box": 6, "cone": 0})
    assert lines[0] == "- Objects with trials: 1 of 2."
    assert "no trials: cone." in lines[1]
    assert lines[2] == "- Labelled grasps per scene with candidates: min 4, median 5, max 6."
    assert _coverage_lines(rows, {"box": 6, "cone": 2})[0] == "- Objects with trials: 2 of 2."


def test_without_a_progress_bar_the_log_gets_a_line_per_card(tmp_path, capsys):
    cfg = datagen.DatagenConfig(out=tmp_path / "log", objects=("cube",), moduli_pa=(2e9,), grasps_per_scene=2,
                                pass_size=1, settings=QUICK, card_every=1)
    assert datagen.generate(cfg, progress_bar=False)["done"] == 2
    lines = [line for line in capsys.readouterr().out.splitlines() if line.startswith("defgg-datagen: ")]
    assert lines and lines[-1].startswith("defgg-datagen: dataset 2 of 2 trials (100.0 %); this run 2 of 2"), lines
    # a resumed run counts what the dataset already holds
    more = replace(cfg, grasps_per_scene=3)
    assert datagen.generate(more, progress_bar=False)["done"] == 1
    lines = [line for line in capsys.readouterr().out.splitlines() if line.startswith("defgg-datagen: ")]
    assert lines[-1].startswith("defgg-datagen: dataset 3 of 3 trials (100.0 %); this run 1 of 1"), lines


def test_an_unknown_object_is_one_clear_line_and_writes_nothing(tmp_path, capsys):
    from defgg_ros.data import datagen_cli

    out = tmp_path / "new"
    assert datagen_cli.main(["--out", str(out), "--objects", "cube", "no_such_object", "--no-progress"]) == 2
    err = capsys.readouterr().err
    assert "objects not in set 'train': ['no_such_object']" in err and "Traceback" not in err
    assert not out.exists()


@pytest.mark.parametrize("argv, says", [(["--moduli", "2e4", "-1"], "--moduli: Young's modulus must be finite"),
                                        (["--candidates", "0"], "--candidates must be >= 1")])
def test_bad_numbers_are_one_clear_line_and_write_nothing(tmp_path, capsys, argv, says):
    from defgg_ros.data import datagen_cli

    out = tmp_path / "new"
    assert datagen_cli.main(["--out", str(out), "--objects", "cube", "--no-progress", *argv]) == 2
    assert says in capsys.readouterr().err and not out.exists()


def test_a_widened_candidate_runs_and_replays_with_its_opening():
    """A candidate the sampler opened wider (sampler 4) carries its opening through the candidate file, the
    job, the trial record and job_from_record; a record without one replays at width + 10 mm as before."""
    from defgg_ros.data.format import TrialRecord
    from defgg_ros.sim.trial import WorldGrasp

    grasp = WorldGrasp((0.0, 0.0, 0.025), 0.0, 0.032, opening_m=0.047)
    fields = datagen.grasp_fields(grasp)
    assert fields["opening_m"] == 0.047 and datagen.world_grasp(fields) == grasp
    rect = {"center_u_px": 0.0, "center_v_px": 0.0, "angle_rad": 0.0, "width_px": 10.0, "finger_height_px": 5.0}
    job = datagen.TrialJob("cone__E2e+09__g000", "cone__E2e+09", "cone", 2e9, 0, fields, rect, 1, QUICK)
    record = datagen.run_trial_job(job.to_dict())
    assert record["sim"]["finger_opening_m"] == 0.047
    replay = datagen.job_from_record(TrialRecord.from_json(record))
    assert replay["grasp"]["opening_m"] == 0.047
    plain = dict(record, sim={k: v for k, v in record["sim"].items() if k != "finger_opening_m"})
    assert "opening_m" not in datagen.job_from_record(TrialRecord.from_json(plain))["grasp"]
    assert "opening_m" not in datagen.grasp_fields(WorldGrasp((0.0, 0.0, 0.025), 0.0, 0.032))


def test_a_new_dataset_presses_and_a_resumed_one_keeps_its_drive(tmp_path):
    """finger_drive: a new dataset's trial hand presses as the cell's; one made before the field keeps the speed
    drive when resumed (its header has no finger_drive: the speed drive every older trial ran)."""
    from defgg_ros.data import datagen_cli
    from defgg_ros.data.format import check_header

    def argv(out, grasps, settings):
        return ["--out", str(out), "--objects", "cube", "--moduli", "2e9", "--grasps-per-scene", str(grasps),
                "--no-progress", "--settings", json.dumps(settings)]

    new, old = tmp_path / "new", tmp_path / "old"
    assert datagen_cli.main(argv(new, 1, QUICK)) == 0
    assert check_header(new)["generator"]["trial_settings"]["finger_drive"] == "press"
    assert datagen_cli.main(argv(new, 2, QUICK)) == 0                    # resumed: one more trial, pressing
    assert [r["sim"]["settings"]["finger_drive"] for r in read_jsonl(new / "trials" / "cube__E2e+09.jsonl")] == \
        ["press", "press"]
    assert datagen_cli.main(argv(old, 1, {**QUICK, "finger_drive": "speed"})) == 0
    assert "finger_drive" not in check_header(old)["generator"]["trial_settings"]
    assert datagen_cli.main(argv(old, 2, QUICK)) == 0                    # resumed: one more trial, the speed drive
    assert len(_trial_ids(old)) == 2
    assert all("finger_drive" not in r["sim"]["settings"] for r in read_jsonl(old / "trials" / "cube__E2e+09.jsonl"))
