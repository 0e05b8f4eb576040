"""Offline pipeline faults: simulations that blow up or run out of time, damaged files.

- A soft body whose simulation runs away (a node metres away or NaN node
  positions written into the real PyBullet state mid-trial; the stable FEM
  settings do not explode on their own) ends the trial as "exploded", with no
  label; so does a sudden burst of kinetic energy (every node jumping 1 m in
  one step, the body still compact: caught by the RMS node-speed check). A
  trial over its CPU budget ends as "timeout"; through the real
  generator such trials are stored (so a restart does not redo them) and
  never become labels.
- A truncated or foreign training-state file on --resume is a clear error.
- A truncated trials file keeps every complete record (the torn tail is the
  only loss) and a damaged scene shard raises DatasetError.
"""
import json
import re

import numpy as np
import pybullet as p
import pytest
import torch

from defgg_ros.data import datagen
from defgg_ros.data.format import (
    LABELLED_STATUSES,
    STATUS_EXPLODED,
    STATUS_TIMEOUT,
    DatasetError,
    list_scene_ids,
    read_scene,
    read_trials,
)
from defgg_ros.sim import objects, world
from defgg_ros.sim.trial import TrialSettings, WorldGrasp, run_grasp_trial

QUICK = TrialSettings().with_fields(close_settle_s=0.05, lift_time_s=0.15, hold_time_s=0.05, shake_ramp_time_s=0.3,
                                    shake_directions=2, time_step_s=0.01)
GRASP = WorldGrasp((0.0, 0.0, 0.02), 0.0, 0.04)


def _sabotage_step_after(monkeypatch, n_steps: int, damage):
    """From the n-th physics step on, damage the first soft body in the real PyBullet state once."""
    real_step = world.World.step
    state = {"steps": 0, "done": False}

    def step(self, n=1):
        state["steps"] += n
        if state["steps"] >= n_steps and not state["done"]:
            state["done"] = True
            damage(self.client)
        return real_step(self, n)

    monkeypatch.setattr(world.World, "step", step)
    return state


def _soft_body(client):
    bodies = [p.getBodyUniqueId(i, physicsClientId=client) for i in range(p.getNumBodies(physicsClientId=client))]
    soft = [b for b in bodies if p.getMeshData(b, -1, flags=p.MESH_DATA_SIMULATION_MESH,
                                               physicsClientId=client)[0] > 0]
    return soft[0]


def _move_node(client, value):
    body = _soft_body(client)
    _, vertices = p.getMeshData(body, -1, flags=p.MESH_DATA_SIMULATION_MESH, physicsClientId=client)
    nodes = np.array(vertices)
    nodes[0] = value
    p.resetMeshData(body, vertices=nodes.tolist(), physicsClientId=client)


def _runaway(client):
    _move_node(client, [5.0, 0.0, 0.0])  # one node metres away: the elements around it tear the body apart


def _nan_nodes(client):
    _move_node(client, [np.nan] * 3)


def _energy_burst(client):
    """Every node jumps 1 m in one step: a 100 m/s body, still compact and near the table."""
    body = _soft_body(client)
    _, vertices = p.getMeshData(body, -1, flags=p.MESH_DATA_SIMULATION_MESH, physicsClientId=client)
    p.resetMeshData(body, vertices=(np.array(vertices) + [1.0, 0.0, 0.0]).tolist(), physicsClientId=client)


@pytest.mark.parametrize("damage,words", [(_runaway, "non-finite or runaway"), (_nan_nodes, "non-finite or runaway"),
                                          (_energy_burst, "energy blow-up")], ids=["runaway", "nan", "energy"])
def test_a_simulation_that_blows_up_mid_trial_is_exploded_and_unlabelled(monkeypatch, damage, words):
    state = _sabotage_step_after(monkeypatch, 10, damage)
    out = run_grasp_trial(objects.ObjectSpec(objects.get_shape("cube"), 2e4), GRASP, ("shake",), QUICK)
    assert state["done"], "the damage was never applied"
    assert out.status == STATUS_EXPLODED, (out.status, out.note)
    assert words in out.note
    assert out.status not in LABELLED_STATUSES and out.shake_accels_mps2 is None


def test_timed_out_trials_are_stored_unlabelled_and_not_rerun(tmp_path):
    settings = {"close_settle_s": 0.05, "lift_time_s": 0.15, "hold_time_s": 0.05, "shake_ramp_time_s": 0.3,
                "max_cpu_s": 0.0}
    cfg = datagen.DatagenConfig(out=tmp_path, objects=("cube",), moduli_pa=(2e9,), grasps_per_scene=2,
                                pass_size=2, settings=settings)
    counts = datagen.generate(cfg, progress_bar=False)
    assert counts["done"] == 2 and counts["failed"] == 2 and counts["labelled"] == 0
    (sid,) = list_scene_ids(tmp_path)
    trials = read_trials(tmp_path, sid)
    assert [t.status for t in trials] == [STATUS_TIMEOUT] * 2
    assert all(t.label is None and "CPU" in t.note for t in trials)
    assert datagen.generate(cfg, progress_bar=False)["done"] == 0  # recorded, so not simulated again


def test_damaged_training_state_on_resume_is_a_clear_error(tmp_path, capsys):
    from defgg_ros.data.synthetic import write_synthetic_dataset
    from defgg_ros.train.cli import main

    data = tmp_path / "data"
    write_synthetic_dataset(data, n_objects=3, trials_per_scene=4, seed=1)
    args = ["--data", str(data), "--epochs", "1", "--batch-size", "2", "--samples-per-scene", "1", "--no-progress",
            "--val-fraction", "0.3", "--test-fraction", "0.3", "--resume"]
    for name, content, words in (("truncated", b"PK\x03\x04 not a whole zip", "cannot read training state"),
                                 ("foreign", None, "not a")):
        out = tmp_path / name
        out.mkdir()
        if content is None:
            torch.save({"format": "something-else"}, out / "state.pt")
        else:
            (out / "state.pt").write_bytes(content)
        assert main(["--out", str(out), *args]) != 0
        err = capsys.readouterr().err
        assert f"{out / 'state.pt'}: {words}" in err and "Traceback" not in err, err
        assert not (out / "model.pt").exists()


def test_torn_trials_file_keeps_every_complete_record_and_a_damaged_scene_raises(tmp_path):
    cfg = datagen.DatagenConfig(out=tmp_path, objects=("cube",), moduli_pa=(2e9,), grasps_per_scene=2,
                                pass_size=2, settings={"close_settle_s": 0.05, "lift_time_s": 0.15,
                                                       "hold_time_s": 0.05, "shake_ramp_time_s": 0.3})
    datagen.generate(cfg, progress_bar=False)
    (sid,) = list_scene_ids(tmp_path)
    trials_path = next((tmp_path / "trials").glob("*.jsonl"))
    complete = trials_path.read_text()
    # A writer killed mid-append leaves half a line: the complete records survive, the torn one is dropped.
    torn = json.dumps({"trial_id": "half"})[:15]
    trials_path.write_text(complete + torn)
    assert [t.trial_id for t in read_trials(tmp_path, sid)] == [json.loads(line)["trial_id"]
                                                               for line in complete.splitlines()]
    # The generator's restart repairs the tail and duplicates nothing.
    assert datagen.generate(cfg, progress_bar=False)["done"] == 0
    assert len(read_trials(tmp_path, sid)) == 2
    scene_path = tmp_path / "scenes" / f"{sid}.npz"
    whole = scene_path.read_bytes()
    flipped = bytearray(whole)
    flipped[len(whole) // 3] ^= 0xFF  # one bit-flipped byte inside the compressed arrays
    for damaged in (whole[:-200], bytes(flipped)):
        scene_path.write_bytes(damaged)
        with pytest.raises(DatasetError, match=re.escape(f"{sid}.npz")):
            read_scene(scene_path)



def test_one_trial_that_raises_does_not_end_the_run_and_is_retried_by_the_next(tmp_path):
    """A damaged candidate (an impossible 0.5 m opening in the cache) makes one trial raise."""
    cfg = datagen.DatagenConfig(out=tmp_path, objects=("cube",), moduli_pa=(2e9,), grasps_per_scene=3,
                                pass_size=3, settings={"close_settle_s": 0.05, "lift_time_s": 0.15,
                                                       "hold_time_s": 0.05, "shake_ramp_time_s": 0.3})
    datagen.plan(cfg, datagen.DatasetWriter(tmp_path, cfg.header()))  # scene + candidate cache, no trials
    cache = tmp_path / "candidates" / "cube.json"
    cached = json.loads(cache.read_text())
    good_width = cached["candidates"][0]["grasp"]["width_m"]
    cached["candidates"][0]["grasp"]["width_m"] = 0.5
    cache.write_text(json.dumps(cached))
    counts = datagen.generate(cfg, progress_bar=False)
    assert counts["done"] == 2 and counts["errors"] == 1
    (sid,) = list_scene_ids(tmp_path)
    assert sorted(t.candidate_index for t in read_trials(tmp_path, sid)) == [1, 2]
    (error,) = [json.loads(line) for line in (tmp_path / datagen.ERRORS_FILE).read_text().splitlines()]
    assert error["trial_id"] == f"{sid}__g000" and "width" in error["error"]
    # Repaired input: the next run simulates exactly the trial that failed.
    cached["candidates"][0]["grasp"]["width_m"] = good_width
    cache.write_text(json.dumps(cached))
    again = datagen.generate(cfg, progress_bar=False)
    assert again["done"] == 1 and again["errors"] == 0
    assert sorted(t.candidate_index for t in read_trials(tmp_path, sid)) == [0, 1, 2]
