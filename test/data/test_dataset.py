"""The torch Dataset over the real on-disk format (synthetic content), and the object split."""
import numpy as np
import pytest
import torch

from defgg_ros.data.augment import AugmentConfig
from defgg_ros.data.dataset import GraspDataset, build_manifest, load_scene_sample, manifest_fingerprint
from defgg_ros.data.format import DatasetWriter, list_scene_ids, read_scene, read_trials
from defgg_ros.data.synthetic import write_synthetic_dataset
from defgg_ros.train.split import split_objects, split_scenes


@pytest.fixture(scope="module")
def synth(tmp_path_factory):
    root = tmp_path_factory.mktemp("synth")
    write_synthetic_dataset(root, n_objects=4, trials_per_scene=20, seed=1)
    return root


def test_items_have_inputs_and_targets(synth):
    ids = list_scene_ids(synth)
    ds = GraspDataset(synth, ids, uses_stiffness=True)
    item = ds[0]
    assert item["x"].shape == (2, 300, 300) and item["y"].shape == (4, 300, 300)
    assert item["x"].dtype == torch.float32
    assert set(np.unique(item["y"][0].numpy())) <= {0.0, 1.0} and item["y"][0].sum() > 0
    assert GraspDataset(synth, ids, uses_stiffness=False)[0]["x"].shape == (1, 300, 300)


def test_only_positive_trials_become_labels(synth):
    sid = list_scene_ids(synth)[0]
    sample = load_scene_sample(synth, sid)
    assert len(sample.positives) == sum(t.label is True for t in read_trials(synth, sid)) > 0


def test_height_filter_keeps_only_positives_near_the_executors_grasp_height(synth):
    """The synthetic trials sit at z = 0, at least 10 mm under any height the executor would use:
    a filter of a metre keeps every positive, one of 5 mm keeps none."""
    sid = list_scene_ids(synth)[0]
    every = load_scene_sample(synth, sid).positives
    assert load_scene_sample(synth, sid, max_height_offset_m=1.0).positives == every and every
    assert load_scene_sample(synth, sid, max_height_offset_m=0.005).positives == []


def test_manifest_freezes_a_growing_dataset(synth, tmp_path):
    manifest = build_manifest(synth)
    fp = manifest_fingerprint(synth, manifest)
    limited = {sid: 0 for sid in manifest}
    ds = GraspDataset(synth, list(manifest), manifest=limited)
    assert len(ds) == 0 and len(ds.skipped_scene_ids) == len(manifest)
    assert manifest_fingerprint(synth, limited) != fp
    assert manifest_fingerprint(synth, manifest) == fp


def test_augmentation_is_a_function_of_seed_epoch_and_index(synth):
    ids = list_scene_ids(synth)[:2]
    ds = GraspDataset(synth, ids, augment=AugmentConfig(), samples_per_scene=3, seed=7)
    assert len(ds) == 6
    a, b = ds[4], ds[4]
    assert torch.equal(a["x"], b["x"]) and torch.equal(a["y"], b["y"])
    assert not torch.equal(ds[4]["x"], ds[5]["x"])
    ds.set_epoch(1)
    assert not torch.equal(ds[4]["x"], a["x"])
    with pytest.raises(IndexError):
        ds[6]


def test_larger_scenes_are_cropped_around_the_object(synth, tmp_path):
    scene = read_scene(synth / "scenes" / f"{list_scene_ids(synth)[0]}.npz")
    big = np.pad(scene.depth_m, ((50, 130), (170, 170)), mode="edge")
    scene.depth_m = big
    scene.youngs_modulus_pa = np.pad(scene.youngs_modulus_pa, ((50, 130), (170, 170)))
    scene.object_mask = np.pad(scene.object_mask, ((50, 130), (170, 170)))
    writer = DatasetWriter(tmp_path / "big")
    writer.write_scene(scene)
    sample = load_scene_sample(tmp_path / "big", scene.scene_id)
    assert sample.depth_m.shape == (300, 300)
    assert sample.object_mask.sum() == scene.object_mask.sum()  # the whole object is in the crop


def test_split_is_by_object():
    names = [f"obj_{i:02d}" for i in range(30)]
    split = split_objects(names, 0.15, 0.15, seed=3)
    assert sorted(sum(split.values(), [])) == names
    assert len(split["val"]) == 4 and len(split["test"]) == 4
    assert not set(split["train"]) & (set(split["val"]) | set(split["test"]))
    scenes = {f"{n}__E{e:.0e}": n for n in names for e in (2e4, 2e5, 2e6, 2e9)}
    by_split = split_scenes(scenes, split)
    for part, ids in by_split.items():
        assert {scenes[s] for s in ids} == set(split[part])   # all moduli of an object together
    assert split_objects(names, 0.15, 0.15, seed=3) == split
    with pytest.raises(ValueError):
        split_objects(["a", "b"], 0.2, 0.2, 0)


def test_the_strict_label_rule_drops_positives_that_slip(synth, tmp_path):
    """--label-rule every_direction: a positive (mean >= 25 m/s^2) that slipped in one direction is
    no longer a ground-truth grasp; the others stay."""
    import json
    import shutil

    root = tmp_path / "copy"
    shutil.copytree(synth, root)
    sid = list_scene_ids(root)[0]
    path = root / "trials" / f"{sid}.jsonl"
    records = [json.loads(line) for line in path.read_text().splitlines()]
    first = next(i for i, t in enumerate(read_trials(root, sid)) if t.label is True)
    records[first]["shake_accels_mps2"] = [50.0] * 8 + [10.0] + [30.0] * 7     # mean 28.1, one slip
    path.write_text("".join(json.dumps(r) + "\n" for r in records))
    mean_rule = load_scene_sample(root, sid)
    strict = load_scene_sample(root, sid, label_rule="every_direction")
    assert read_trials(root, sid)[first].label is True
    assert len(strict.positives) == len(mean_rule.positives) - 1 > 0
    with pytest.raises(ValueError, match="label rule"):
        load_scene_sample(root, sid, label_rule="median")
