"""Every defgg-* command's --help shows the defaults that say something, once, also in subcommands."""
import re

import pytest

from defgg_ros.bringup.cli import parse_args as bringup_args
from defgg_ros.data.datagen_cli import build_parser as datagen_parser
from defgg_ros.data.datagen_cli import build_signal_parser
from defgg_ros.evaluation.cli import build_parser as eval_parser
from defgg_ros.sessions.record import build_parser as record_parser
from defgg_ros.train.cli import build_parser as train_parser

pytestmark = pytest.mark.unit


def _help(parser, *subcommand) -> str:
    if subcommand:
        sub = next(a for a in parser._actions if a.choices and subcommand[0] in a.choices)
        parser = sub.choices[subcommand[0]]
    return re.sub(r"\s+", " ", parser.format_help())


def test_options_show_their_defaults_once():
    datagen = _help(datagen_parser())
    assert "--grasps-per-scene" in datagen and "(default: 40)" in datagen
    assert "--workers" in datagen and "default: None" not in datagen   # silent defaults stay silent
    train = _help(train_parser())
    assert train.count("(default: 0.001)") == 1 and "default: 0.001) (default" not in train   # said once
    assert "(default: False)" not in train                                               # flags


def test_subcommands_get_the_formatter_too():
    assert "object of the common/adversarial set (default: common_toy_bone)" in _help(eval_parser(), "strategy")
    run = _help(eval_parser(), "run")
    assert run.count("(default 1)") == 1 and "(default 1) (default" not in run   # its own wording kept


def test_usage_names_the_datagen_subcommands_and_plan_indices_count_from_zero():
    usage = datagen_parser().format_usage()
    assert "defgg-datagen signal FOLDER" in usage and "defgg-datagen seal FOLDER" in usage
    assert "(default:" not in _help(build_signal_parser()).split("--png")[0].split("--json")[1]
    assert "0 = the first PlanGrasp" in _help(record_parser())
    with pytest.raises(SystemExit):
        bringup_args(["--help"])
