"""The dataset card's notes follow the dataset's recorded protocol."""
from defgg_ros.data.card import _last_column_note


def test_the_last_column_note_names_the_evaluation_criterion_of_the_protocol():
    # defgraspsim: the evaluation's shake success is the label's mean; every direction is its second table
    defgraspsim = _last_column_note({"trial_settings": {"protocol": "defgraspsim"}})
    assert "second shake table" in defgraspsim and "where every direction must hold" not in defgraspsim
    # legacy (fem_v1-v4, no recorded settings): the evaluation's shake needed every direction
    legacy = _last_column_note({})
    assert "where every direction must hold" in legacy and "second shake table" not in legacy
