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
