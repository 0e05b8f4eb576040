"""defgg-train's options reach the TrainConfig that is stored with every run."""
import pytest

from defgg_ros.train.cli import build_parser, config_from_args
from defgg_ros.train.config import TrainConfig


def test_height_filter_option_is_in_metres_and_round_trips():
    args = build_parser().parse_args(["--data", "d", "--out", "o", "--max-height-offset-mm", "5"])
    config = config_from_args(args)
    assert config.max_height_offset_m == pytest.approx(0.005)
    assert TrainConfig.from_dict(config.to_dict()) == config
    assert config_from_args(build_parser().parse_args(["--data", "d", "--out", "o"])).max_height_offset_m is None


def test_negative_height_filter_is_refused():
    with pytest.raises(ValueError, match="max_height_offset_m"):
        TrainConfig(max_height_offset_m=-0.001)


@pytest.mark.parametrize("field, value, says", [
    ("epochs", 0, "epochs must be >= 1"), ("batch_size", 0, "batch_size must be >= 1"),
    ("samples_per_scene", 0, "samples_per_scene must be >= 1"), ("max_steps", 0, "max_steps must be >= 1"),
    ("learning_rate", 0.0, "learning_rate must be > 0"), ("positive_weight", -1.0, "positive_weight must be > 0"),
    ("val_fraction", 0.6, "sum below 1"), ("test_fraction", 0.0, "must be > 0")])
def test_hyper_parameters_out_of_range_are_refused_before_any_data_is_read(field, value, says):
    with pytest.raises(ValueError, match=says):
        TrainConfig(**{field: value, **({"test_fraction": 0.4} if field == "val_fraction" else {})})


def test_the_cli_says_what_is_wrong_in_one_line(tmp_path, capsys):
    from defgg_ros.train.cli import main

    assert main(["--data", str(tmp_path), "--out", str(tmp_path / "run"), "--epochs", "0"]) == 2
    assert capsys.readouterr().err.strip() == "defgg-train: error: epochs must be >= 1, got 0"
    assert not (tmp_path / "run").exists()


def test_objects_without_any_trial_take_no_validation_or_test_slot(tmp_path):
    from defgg_ros.data.dataset import build_manifest
    from defgg_ros.data.synthetic import write_synthetic_dataset
    from defgg_ros.train.trainer import labelled_scene_objects

    write_synthetic_dataset(tmp_path, n_objects=4, trials_per_scene=2)
    manifest = build_manifest(tmp_path)
    objects = labelled_scene_objects(tmp_path, manifest)
    assert len(objects) == len(manifest) and len(set(objects.values())) == 4
    unlabelled = sorted(set(objects.values()))[0]
    for path in (tmp_path / "trials").glob(f"{unlabelled}__*"):
        path.unlink()                              # as for an object the sampler found no candidate for
    objects = labelled_scene_objects(tmp_path, build_manifest(tmp_path))
    assert unlabelled not in objects.values() and len(set(objects.values())) == 3


def test_a_seed_study_keeps_the_object_split_of_its_split_seed(tiny_dataset, tmp_path):
    """--split-seed fixes the validation objects while --seed changes init, order and augmentation, so
    seeds are compared (and the shipped one chosen) on the same validation objects."""
    from defgg_ros.train.cli import main

    def split_of(*flags):
        out = tmp_path / "_".join(flags).replace("-", "")
        assert main(["--data", str(tiny_dataset), "--out", str(out), "--epochs", "1", "--max-steps", "1",
                     "--no-progress", "--val-fraction", "0.34", "--test-fraction", "0.33", *flags]) == 0
        import torch
        return torch.load(out / "state.pt", weights_only=True)["object_split"]

    base = split_of("--seed", "0")
    assert split_of("--seed", "5", "--split-seed", "0") == base
    assert any(split_of("--seed", str(s)) != base for s in (1, 2, 3))
    args = build_parser().parse_args(["--data", "d", "--out", "o", "--seed", "3", "--split-seed", "0"])
    config = config_from_args(args)
    assert (config.seed, config.object_split_seed) == (3, 0)
    assert TrainConfig.from_dict(config.to_dict()) == config


def test_a_fixed_split_keeps_its_validation_objects_whatever_the_data_adds():
    """--val-objects (issue 49): the validation objects stay the ones named when objects are added or the test
    part moves into training; the options round-trip; a config without them stores neither key (runs started
    before the option resume)."""
    from defgg_ros.train.split import fixed_split

    args = build_parser().parse_args(["--data", "d", "--out", "o", "--val-objects", "sphere", "cube",
                                      "--test-objects", "cone"])
    config = config_from_args(args)
    assert config.val_objects == ("sphere", "cube") and config.test_objects == ("cone",)
    assert TrainConfig.from_dict(config.to_dict()) == config
    assert "val_objects" not in TrainConfig().to_dict()
    assert TrainConfig.from_dict(TrainConfig().to_dict()) == TrainConfig()
    names = ["box", "cone", "cube", "sphere", "torus"]
    assert fixed_split(names, ["sphere", "cube"]) == {"val": ["cube", "sphere"], "test": [],
                                                      "train": ["box", "cone", "torus"]}
    assert fixed_split(names + ["mug"], ["sphere", "cube"], ["cone"])["val"] == ["cube", "sphere"]
    for val, test, says in ((["pear"], [], "no labelled scene"), ([], [], "at least one validation"),
                            (["cube"], ["cube"], "both in validation and test"),
                            (names, [], "leave objects to train")):
        with pytest.raises(ValueError, match=says):
            fixed_split(names, val, test)
    with pytest.raises(ValueError, match="test_objects need val_objects"):
        TrainConfig(test_objects=("cone",))


def test_zero_threads_is_a_usage_error_not_a_traceback(capsys):
    from defgg_ros.train.cli import main

    with pytest.raises(SystemExit) as exit_info:
        main(["--data", "d", "--out", "o", "--threads", "0"])
    assert exit_info.value.code == 2 and "--threads must be >= 1, got 0" in capsys.readouterr().err
