"""LatestFrameWorker (perception on arrival): which frame a request gets, drops, errors, priority, close.

The worker's prepare function is driven by events, so every case is deterministic; the waits below only
guard against a hang (no assertion depends on how long anything took)."""
import threading
import time

import pytest

from defgg_ros.perception.frame_worker import LatestFrameWorker, RecentValues, WorkerClosed

GUARD_S = 20.0


class Clock:
    def __init__(self):
        self.now = 100.0

    def __call__(self):
        return self.now


class Prepare:
    """prepare(frame, checkpoint): records the frame and its thread; frames in `hold` wait for their release
    event between two checkpoints; frames named 'bad' raise ValueError, 'boom' RuntimeError."""

    def __init__(self, hold=()):
        self.started = {}                 # frame -> threading.Event set when its preparation starts
        self.release = {f: threading.Event() for f in hold}
        self.threads = {}
        self.passed_checkpoint = {}       # frame -> Event: got past its first checkpoint
        self.calls = []

    def event(self, table, frame):
        return table.setdefault(frame, threading.Event())

    def __call__(self, frame, checkpoint):
        self.calls.append(frame)
        self.threads[frame] = threading.current_thread()
        self.event(self.started, frame).set()
        if frame in self.release:
            assert self.release[frame].wait(GUARD_S), f"{frame} never released"
        checkpoint()
        self.event(self.passed_checkpoint, frame).set()
        if frame == "bad":
            raise ValueError("no table in the workspace")
        if frame == "boom":
            raise RuntimeError("a bug")
        return f"result of {frame}"


def wait(event, what):
    assert event.wait(GUARD_S), f"timed out waiting for {what}"


@pytest.fixture
def make():
    workers = []

    def build(prepare, max_age_s=0.1, **kwargs):
        worker = LatestFrameWorker(prepare, max_age_s, **kwargs)
        workers.append(worker)
        return worker

    yield build
    for worker in workers:
        worker.close()


def prepared_frames(worker, count):
    """Block until the worker has prepared `count` frames."""
    with worker._cond:
        assert worker._cond.wait_for(lambda: worker.prepared >= count, GUARD_S), "frames not prepared"


def test_nothing_submitted_gives_none_and_each_frame_is_prepared_once_in_the_worker(make):
    prepare = Prepare()
    worker = make(prepare, max_age_s=0.0)
    assert worker.latest() is None
    worker.submit("a")
    prepared_frames(worker, 1)
    done = worker.latest()
    assert (done.seq, done.frame, done.value()) == (1, "a", "result of a")
    assert prepare.threads["a"] is worker._thread
    assert worker.latest() is done and prepare.calls == ["a"]     # asked again: not prepared again


def test_frames_arriving_faster_than_perception_keep_only_the_newest(make):
    prepare = Prepare(hold=("a",))
    worker = make(prepare, max_age_s=0.0)
    worker.submit("a")
    wait(prepare.event(prepare.started, "a"), "a to start")
    for frame in ("b", "c", "d"):
        worker.submit(frame)
    prepare.release["a"].set()
    prepared_frames(worker, 2)
    assert prepare.calls == ["a", "d"] and worker.dropped == 2
    assert worker.latest().frame == "d"


def test_a_fresh_perceived_frame_answers_while_a_newer_one_is_being_perceived(make):
    clock = Clock()
    prepare = Prepare(hold=("b",))
    worker = make(prepare, clock=clock)
    worker.submit("a")
    prepared_frames(worker, 1)
    clock.now += 0.05
    worker.submit("b")
    wait(prepare.event(prepare.started, "b"), "b to start")
    assert worker.latest().frame == "a"          # a arrived 0.05 s ago: fresh enough, no waiting
    prepare.release["b"].set()


def test_a_stale_perceived_frame_makes_the_request_wait_for_the_latest_one(make):
    clock = Clock()
    prepare = Prepare(hold=("b",))
    worker = make(prepare, clock=clock)
    worker.submit("a")
    prepared_frames(worker, 1)
    clock.now += 0.5
    worker.submit("b")
    wait(prepare.event(prepare.started, "b"), "b to start")
    answer = {}
    request = threading.Thread(target=lambda: answer.setdefault("done", worker.latest()))
    request.start()
    request.join(0.2)
    assert request.is_alive(), "the request must wait for b, not answer from the stale a"
    prepare.release["b"].set()
    request.join(GUARD_S)
    assert answer["done"].frame == "b" and prepare.threads["b"] is worker._thread


def test_a_bounded_wait_answers_from_the_newest_prepared_frame_when_the_latest_is_not_ready(make):
    """Fresh answers under load (issue 47.4): with wait_s the request waits that long at most, then answers from
    the newest prepared frame; it prepares nothing itself, the stage goes on with the newest."""
    clock = Clock()
    prepare = Prepare(hold=("b", "c"))
    worker = make(prepare, clock=clock)
    worker.submit("a")
    prepared_frames(worker, 1)
    clock.now += 0.5                              # a is stale (max_age_s 0.1) once b arrives
    worker.submit("b")
    wait(prepare.event(prepare.started, "b"), "b to start")
    worker.submit("c")                            # waits behind b at the stage's input
    assert worker.latest(wait_s=0.05).frame == "a"    # neither b nor c is ready: the newest prepared one
    assert "c" not in prepare.threads             # not prepared by the request
    prepare.release["b"].set()
    prepare.release["c"].set()
    prepared_frames(worker, 2)
    with worker._cond:
        assert worker._cond.wait_for(lambda: worker._done.frame == "c", GUARD_S)
    assert worker.latest(wait_s=0.05).frame == "c" and prepare.threads["c"] is worker._thread


def test_a_bounded_wait_does_not_answer_from_a_frame_from_before_a_pause_of_the_stream(make):
    """The camera paused (the simulated one does while the arm moves), then one new frame came: a request with
    wait_s waits for that frame, not the pre-pause one (it answered the 2.5 s old scene from before the pick)."""
    from defgg_ros.perception.frame_worker import STALE_FALLBACK_S

    clock = Clock()
    prepare = Prepare(hold=("after pause",))
    worker = make(prepare, clock=clock)
    worker.submit("before pause")
    prepared_frames(worker, 1)
    clock.now += 0.1 + STALE_FALLBACK_S + 1.4
    worker.submit("after pause")
    wait(prepare.event(prepare.started, "after pause"), "the new frame to start")
    answer = {}
    request = threading.Thread(target=lambda: answer.update(done=worker.latest(wait_s=0.05)))
    request.start()
    request.join(0.5)
    assert request.is_alive()                       # waiting for the new frame, not answering the old one
    prepare.release["after pause"].set()
    request.join(GUARD_S)
    assert answer["done"].frame == "after pause"


def test_max_age_zero_always_answers_from_the_latest_frame(make):
    prepare = Prepare(hold=("b",))
    worker = make(prepare, max_age_s=0.0)
    worker.submit("a")
    prepared_frames(worker, 1)
    worker.submit("b")
    wait(prepare.event(prepare.started, "b"), "b to start")
    threading.Timer(0.05, prepare.release["b"].set).start()
    assert worker.latest().frame == "b"


def test_an_unstarted_latest_frame_is_perceived_by_the_request_and_the_worker_drops_its_older_one(make):
    clock = Clock()
    prepare = Prepare(hold=("a",))
    worker = make(prepare, clock=clock)
    worker.submit("a")
    wait(prepare.event(prepare.started, "a"), "a to start")
    worker.submit("b")                     # waits behind a
    done = worker.latest()              # nothing perceived yet: the request takes b itself
    assert done.frame == "b" and prepare.threads["b"] is threading.current_thread()
    prepare.release["a"].set()
    with worker._cond:
        assert worker._cond.wait_for(lambda: worker.superseded == 1, GUARD_S)
    assert not prepare.event(prepare.passed_checkpoint, "a").is_set()   # a stopped at its checkpoint: b is newer
    assert worker.latest() is done and worker.prepared == 1


def test_bad_frames_give_their_error_and_the_worker_goes_on(make):
    errors = []
    prepare = Prepare()
    worker = make(prepare, max_age_s=0.0, on_error=lambda frame, exc: errors.append((frame, exc)))
    worker.submit("bad")
    prepared_frames(worker, 1)
    with pytest.raises(ValueError, match="no table"):
        worker.latest().value()
    worker.submit("boom")
    prepared_frames(worker, 2)
    with pytest.raises(RuntimeError, match="internal error.*a bug"):
        worker.latest().value()
    assert [frame for frame, _ in errors] == ["boom"]
    worker.submit("good")
    prepared_frames(worker, 3)
    assert worker.latest().value() == "result of good"


@pytest.mark.parametrize("paused_s", [0.05, 0.5])
def test_the_worker_waits_at_its_checkpoints_while_a_request_has_priority(make, paused_s):
    """And drops its frame there when it became older than max_age_s (0.1 s) meanwhile and a newer one waits."""
    clock = Clock()
    prepare = Prepare(hold=("a",))
    worker = make(prepare, clock=clock)
    worker.submit("a")
    wait(prepare.event(prepare.started, "a"), "a to start")
    with worker.priority():
        prepare.release["a"].set()
        assert not prepare.event(prepare.passed_checkpoint, "a").wait(0.2)
        worker.submit("b")
        assert not prepare.event(prepare.started, "b").wait(0.2), "no new frame is started under priority"
        clock.now += paused_s
    wait(prepare.event(prepare.passed_checkpoint, "b"), "b once priority ended")
    stale = paused_s > worker.max_age_s
    assert prepare.event(prepare.passed_checkpoint, "a").is_set() is not stale
    assert worker.superseded == int(stale)


def test_on_prepared_runs_in_the_worker_for_each_frame_it_prepared(make):
    seen, both = [], threading.Event()

    def on_prepared(done, checkpoint):
        seen.append((done.frame, checkpoint(), threading.current_thread()))
        if len(seen) == 2:
            both.set()

    worker = make(Prepare(), on_prepared=on_prepared)
    worker.submit("a")
    prepared_frames(worker, 1)
    worker.submit("b")
    wait(both, "on_prepared of both frames")
    assert seen == [("a", None, worker._thread), ("b", None, worker._thread)]


def test_close_ends_waiting_requests_and_refuses_new_frames(make):
    clock = Clock()
    prepare = Prepare(hold=("b",))
    worker = make(prepare, clock=clock)
    worker.submit("a")
    prepared_frames(worker, 1)
    clock.now += 1.0
    worker.submit("b")
    wait(prepare.event(prepare.started, "b"), "b to start")
    threading.Timer(0.05, worker.close).start()
    with pytest.raises(WorkerClosed):
        worker.latest()
    prepare.release["b"].set()
    with pytest.raises(WorkerClosed):
        worker.submit("c")


class Network(Prepare):
    """A second stage: prepare's result -> 'planned <result>'; holds and errors keyed by the frame's name."""

    def __call__(self, value, checkpoint):
        frame = value.removeprefix("result of ")
        return "planned " + super().__call__(frame, checkpoint)


def test_two_stages_work_on_consecutive_frames_at_once_and_give_the_stages_in_sequence(make):
    perceive, network = Prepare(), Network(hold=("a",))
    worker = make((perceive, network), max_age_s=0.0)
    worker.submit("a")
    wait(network.event(network.started, "a"), "a in the second stage")
    worker.submit("b")
    with worker._cond:      # b through the first stage while a is held in the second: the stages overlap
        assert worker._cond.wait_for(lambda: worker._inbox[1] is not None and worker._inbox[1].seq == 2, GUARD_S)
    assert not worker.done
    network.release["a"].set()
    prepared_frames(worker, 2)
    assert [worker.latest().value(), worker.prepared, worker.dropped] == ["planned result of b", 2, 0]
    assert perceive.threads["a"] is perceive.threads["b"] is not network.threads["a"]
    assert network.threads["b"] is worker._thread and worker.stages == 2


def test_an_error_of_the_first_stage_skips_the_second(make):
    perceive, network = Prepare(), Network()
    worker = make((perceive, network), max_age_s=0.0)
    worker.submit("bad")
    prepared_frames(worker, 1)
    with pytest.raises(ValueError, match="no table"):
        worker.latest().value()
    assert network.calls == []


def test_a_request_runs_the_second_stage_of_a_latest_frame_waiting_for_it(make):
    """The second stage is busy with an older frame: the request takes the newest frame from its input."""
    perceive, network = Prepare(), Network(hold=("a",))
    worker = make((perceive, network), max_age_s=0.0)
    worker.submit("a")
    wait(network.event(network.started, "a"), "a in the second stage")
    worker.submit("b")
    with worker._cond:
        assert worker._cond.wait_for(lambda: worker._inbox[1] is not None, GUARD_S)
    done = worker.latest()
    assert done.value() == "planned result of b" and network.threads["b"] is threading.current_thread()
    assert perceive.threads["b"] is not threading.current_thread()      # its first stage ran in the worker
    network.release["a"].set()
    with worker._cond:
        assert worker._cond.wait_for(lambda: worker.superseded == 1, GUARD_S)
    assert not network.event(network.passed_checkpoint, "a").is_set() and worker.latest() is done


def test_recent_values_forget_after_their_window():
    now = [100.0]
    recent = RecentValues(5.0, clock=lambda: now[0])
    recent.note(3)
    now[0] += 4.0
    recent.note(5)
    assert recent.recent() == {3, 5}
    now[0] += 1.5                      # 3 was noted 5.5 s ago, 5 1.5 s ago
    assert recent.recent() == {5}
    recent.note(3)
    assert recent.recent() == {3, 5}
    off = RecentValues(0.0, clock=lambda: now[0])
    off.note(3)
    assert off.recent() == set()
    with pytest.raises(ValueError, match="window_s"):
        RecentValues(-1.0)


def test_a_busy_fraction_makes_the_stage_rest_after_each_frame_and_keep_only_the_newest(make):
    """max_busy_fraction 0.5: after a frame that took >= 0.1 s the stage rests as long again before it starts
    the next; frames that arrived meanwhile are dropped but the newest. (Lower bounds only: a slow machine
    can make the rest longer, never shorter.)"""
    starts, ends = {}, {}

    def slow(frame, checkpoint):
        starts[frame] = time.monotonic()
        time.sleep(0.1)
        ends[frame] = time.monotonic()
        return frame

    worker = make(slow, max_age_s=0.0, max_busy_fraction=0.5)
    worker.submit("a")
    prepared_frames(worker, 1)
    for frame in ("b", "c"):
        worker.submit(frame)
    prepared_frames(worker, 2)
    assert worker.latest().frame == "c" and worker.dropped == 1 and "b" not in starts
    assert starts["c"] - ends["a"] >= 0.1 - 1e-3
    assert worker.rested_s >= 0.1 - 1e-3


def test_a_busy_fraction_outside_0_1_is_refused(make):
    for fraction in (0.0, -0.5, 1.5):
        with pytest.raises(ValueError, match="max_busy_fraction"):
            make(Prepare(), max_busy_fraction=fraction)


def test_the_rest_follows_the_average_frame_time_so_one_slow_frame_leaves_no_long_gap(make):
    """Rests after frames of 50, 50, 50 then 300 ms at max_busy_fraction 0.5: 50, 50, 50 then 100 ms (the moving
    average, weight 0.2), not 300 ms (the last frame's time alone gave a gap as long as the slow frame)."""
    worker = make(Prepare(), max_busy_fraction=0.5)
    rests = []
    for busy_s in (0.05, 0.05, 0.05, 0.3):
        before = worker.rested_s
        worker._rest(0, busy_s)
        rests.append(worker.rested_s - before)
    assert rests == pytest.approx([0.05, 0.05, 0.05, 0.1])
