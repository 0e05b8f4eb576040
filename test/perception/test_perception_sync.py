"""The exact-stamp synchroniser used by the grasp inference node."""
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from defgg_ros.perception.sync import StampSynchronizer


def test_emits_when_all_streams_have_the_stamp():
    sync = StampSynchronizer(("depth", "stiffness", "info"))
    assert sync.add("depth", 100, "d100") is None
    assert sync.add("info", 100, "i100") is None
    assert sync.add("stiffness", 100, "s100") == {"depth": "d100", "stiffness": "s100", "info": "i100"}


def test_out_of_order_and_interleaved_frames():
    sync = StampSynchronizer(("depth", "stiffness"))
    for stamp in (1, 2, 3):
        assert sync.add("depth", stamp, f"d{stamp}") is None
    assert sync.add("stiffness", 2, "s2") == {"depth": "d2", "stiffness": "s2"}
    assert sync.dropped == 1  # d1 can never complete any more
    assert sync.add("stiffness", 1, "s1") is None  # older than the emitted set
    assert sync.add("stiffness", 3, "s3") == {"depth": "d3", "stiffness": "s3"}


def test_a_clock_that_starts_again_is_matched_afresh():
    """A bag played with --loop, a restarted simulator: stamps go back by more than CLOCK_RESTART_NS. Matching
    starts again (it stopped for good: every later frame was 'older than the last emitted set'); a frame only
    late (within it) is still dropped."""
    from defgg_ros.perception.sync import CLOCK_RESTART_NS

    sync = StampSynchronizer(("depth", "stiffness"))
    later = 100 * CLOCK_RESTART_NS
    sync.add("depth", later, "d")
    assert sync.add("stiffness", later, "s") == {"depth": "d", "stiffness": "s"}
    assert sync.add("depth", later - CLOCK_RESTART_NS // 2, "late") is None and sync.dropped == 1
    assert sync.add("depth", 1, "d1") is None
    assert sync.add("stiffness", 1, "s1") == {"depth": "d1", "stiffness": "s1"}
    assert sync.add("depth", 2, "d2") is None and sync.add("stiffness", 2, "s2") == {"depth": "d2",
                                                                                      "stiffness": "s2"}


def test_cache_is_bounded():
    sync = StampSynchronizer(("depth", "stiffness"), cache_size=3)
    for stamp in range(10):
        sync.add("depth", stamp, stamp)
    assert sync.pending("depth") == 3 and sync.dropped == 7
    assert sync.add("stiffness", 2, "s") is None  # evicted
    assert sync.add("stiffness", 9, "s") == {"depth": 9, "stiffness": "s"}


def test_bad_arguments():
    with pytest.raises(ValueError):
        StampSynchronizer(("a", "a"))
    with pytest.raises(ValueError):
        StampSynchronizer(("a",), cache_size=0)
    with pytest.raises(KeyError, match="unknown stream"):
        StampSynchronizer(("a",)).add("b", 1, None)


@settings(max_examples=60, deadline=None)
@given(st.lists(st.tuples(st.sampled_from(["a", "b"]), st.integers(0, 20)), max_size=80))
def test_emitted_sets_are_exact_and_increasing(events):
    sync = StampSynchronizer(("a", "b"), cache_size=4)
    emitted = []
    for stream, stamp in events:
        out = sync.add(stream, stamp, (stream, stamp))
        if out is not None:
            assert out["a"][1] == out["b"][1] == stamp
            emitted.append(stamp)
        assert sync.pending("a") <= 4 and sync.pending("b") <= 4
    assert emitted == sorted(set(emitted))
