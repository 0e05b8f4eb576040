"""Perception on arrival: worker threads prepare each frame as it arrives, requests take the result (no rclpy).

    worker = LatestFrameWorker(prepare, max_age_s=0.3)   # prepare(frame, checkpoint) -> result; ValueError: bad
    worker = LatestFrameWorker((perceive, plan), 0.3)    # a pipeline: plan(perceive(frame, cp), cp) -> result
    worker.submit(frame)                     # from the subscription callback, every synchronised frame
    done = worker.latest()                   # in a request: a WorkerResult (None: no frame yet)
    with worker.priority():                  # the request's own work; the worker waits at its checkpoints
        answer(done.value())

Stages: `prepare` may be a sequence of functions, each run by its own thread on the previous one's output,
so consecutive frames are in different stages at once (two cores: one perceives frame n + 1 while the
other runs the network on frame n; the stages must release the interpreter enough, as numpy, OpenCV and
torch do). The result is the same as running the stages one after the other in one thread.

Rules (docs/perception.md, "Latency"):
- Only the newest unprocessed frame is kept at each stage's input: a frame handed on while another waits
  there replaces it (dropped).
- `latest()` answers from the newest prepared frame when it is the newest submitted frame or was
  submitted at most max_age_s before the call (clock: time.monotonic, when the frame was submitted, not its
  stamp). Otherwise from the newest submitted frame: the call waits for the worker when a stage is on it,
  else takes it from the stage input it waits at and runs the remaining stages itself. So an answer never
  comes from a frame older than the newest prepared one, nor older than max_age_s while a newer frame exists.
  With `latest(wait_s=...)` (bounded latency under load) the call waits at most wait_s for the stages to
  finish the newest frame and otherwise answers from the newest prepared one (it prepares nothing itself
  once a frame was prepared): an answer then never waits longer than wait_s, and its frame is as fresh as
  the stages keep up. Unless that frame is more than max_age_s + STALE_FALLBACK_S old (the stream paused, as
  a simulated camera does while the arm moves, then sent a new frame): the newest frame is then answered
  from as without wait_s.
- A frame whose preparation raised ValueError (in any stage) is a prepared frame too: requests get its error.
- max_busy_fraction f < 1: after each frame a stage thread rests busy_s * (1/f - 1) (wall clock) before it takes
  the next, so it keeps at most the fraction f of a core and frames arriving meanwhile are dropped (newest wins).
  busy_s is a moving average of the frames' times (BUSY_AVERAGE_WEIGHT), so one slow frame does not leave a long
  gap without a fresh frame. On a busy machine frames take longer, so the rest grows with them: the stage backs
  off instead of queueing work behind the other processes (docs/perception.md, "Fresh answers under load").
- While a request holds `priority()` the stage threads wait at their next checkpoint (the stage functions
  call `checkpoint()` between their steps) and start no new frame, so the request's work does not share the
  interpreter with them. A frame that a request prepared itself makes the stages drop the older frames they
  are on at their next checkpoint; a frame that became older than max_age_s while a stage waited is dropped
  when a newer frame was submitted (no request could use it any more).
"""
from __future__ import annotations

import contextlib
import dataclasses
import functools
import sys
import threading
import time
from dataclasses import dataclass

# The interpreter's switch interval in a node whose worker threads run Python-heavy perception or search beside
# its executor: a thread that released the interpreter (a DDS wait, a take, a send) waits up to this long to get it
# back from a busy worker, several times per service call. Python's default, 5 ms, made a PlanGrasp lookup of
# 0.1 ms take tens of ms in the node under load (docs/perception.md, "Fresh answers under load").
RESPONSIVE_SWITCH_INTERVAL_S = 0.0005


def keep_executor_responsive() -> None:
    """Shorten this process's interpreter switch interval (RESPONSIVE_SWITCH_INTERVAL_S); never lengthens it."""
    sys.setswitchinterval(min(sys.getswitchinterval(), RESPONSIVE_SWITCH_INTERVAL_S))


# The longest rest after one frame (max_busy_fraction): a frame that took seconds (a stall) must not leave the
# stage idle for longer than this.
MAX_REST_S = 1.0
# Weight of the newest frame in the moving average of the time a frame takes (max_busy_fraction's rest). With the
# last frame's time alone, one slow frame (a 80 ms frame where 43 ms is usual) made a 110 ms rest: the answers'
# frame age p99 followed those gaps (bench_fresh_answers, 2026-11-29).
BUSY_AVERAGE_WEIGHT = 0.2
# latest(wait_s=...) answers from an older prepared frame only while it is at most this much older than max_age_s:
# past it, the stream paused (a 2.5 s old pre-pick scene was answered after the pause), and the newest is worth
# its wait.
STALE_FALLBACK_S = 1.0


class WorkerClosed(RuntimeError):
    """The worker was closed (the node is shutting down)."""


class _Superseded(Exception):
    """Raised at a checkpoint: a newer frame is already prepared, this one is not needed."""


@dataclass(frozen=True)
class WorkerResult:
    seq: int                      # 1, 2, ... in submission order
    frame: object                 # what was submitted
    submitted_s: float            # time.monotonic() at submit()
    result: object = None
    error: Exception | None = None

    def value(self):
        """The result, or the preparation's error raised again."""
        if self.error is not None:
            raise self.error
        return self.result


@dataclass(frozen=True)
class _Item:
    """A frame between stages: the last stage's output (the frame itself before the first), or its error."""
    seq: int
    frame: object
    submitted_s: float
    value: object
    error: Exception | None = None


def _no_checkpoint() -> None:
    pass


class LatestFrameWorker:
    def __init__(self, prepare, max_age_s: float, on_prepared=None, name: str = "perception_on_arrival",
                 clock=time.monotonic, on_error=None, max_busy_fraction: float = 1.0):
        """prepare(frame, checkpoint) -> result, or a sequence of such stage functions (module docstring).
        max_age_s: the freshness rule's age. on_prepared(prepared, checkpoint): called in the last stage's
        thread after each frame it prepared is stored (e.g. publish its grasps). on_error(frame, exception):
        an unexpected (non-ValueError) exception of a stage; the frame's requests get it as their error.
        max_busy_fraction: in (0, 1], the most of a core each stage thread takes (module docstring)."""
        if not 0.0 < max_busy_fraction <= 1.0:
            raise ValueError(f"max_busy_fraction must be in (0, 1], got {max_busy_fraction}")
        self._rest_per_busy = 1.0 / max_busy_fraction - 1.0
        self._stages = tuple(prepare) if isinstance(prepare, (tuple, list)) else (prepare,)
        if not self._stages:
            raise ValueError("at least one stage")
        self.max_age_s = float(max_age_s)
        self._on_prepared = on_prepared
        self._on_error = on_error
        self._clock = clock
        self._cond = threading.Condition()
        n = len(self._stages)
        self._inbox = [None] * n      # per stage: the _Item waiting for it, not started yet
        self._in_flight = [None] * n  # per stage: the _Item its thread is on
        self._done = None             # the newest WorkerResult
        self._claimed = 0             # the newest seq a request took from a stage input
        self._priority = 0            # requests holding priority()
        self._closed = False
        self.submitted = 0            # frames submitted
        self.prepared = 0             # frames prepared (by the worker or by requests)
        self.dropped = 0              # frames replaced at a stage input before that stage started them
        self.superseded = 0           # frames a stage stopped because a newer one was prepared
        self.rested_s = 0.0           # wall time the stage threads rested (max_busy_fraction)
        self._busy_average_s = [None] * n   # per stage: moving average of a frame's time
        self._threads = [threading.Thread(target=self._run, args=(index,), daemon=True,
                                          name=name if n == 1 else f"{name}_{index + 1}") for index in range(n)]
        self._thread = self._threads[-1]    # the last stage's: on_prepared runs there
        for thread in self._threads:
            thread.start()

    @property
    def stages(self) -> int:
        return len(self._stages)

    # --- producer --------------------------------------------------------------------------------
    def submit(self, frame) -> int:
        """Queue `frame` as the newest; an unstarted older frame is dropped. Returns its seq."""
        with self._cond:
            if self._closed:
                raise WorkerClosed("the perception worker is closed")
            self.submitted += 1
            self._put(0, _Item(self.submitted, frame, self._clock(), frame))
            return self.submitted

    def _put(self, index: int, item: _Item) -> None:
        """Under the lock: item waits for stage `index`, replacing an older unstarted one."""
        if self._inbox[index] is not None:
            self.dropped += 1
        self._inbox[index] = item
        self._cond.notify_all()

    # --- consumer --------------------------------------------------------------------------------
    def latest(self, timeout_s: float = 30.0, wait_s: float | None = None) -> WorkerResult | None:
        """The prepared frame to answer a request from (module docstring); None when nothing was submitted.
        wait_s (bounded latency): when a prepared frame exists but is not fresh enough, wait at most wait_s for
        the stages to finish the newest frame, then answer from the newest prepared frame; unless that frame is
        over max_age_s + STALE_FALLBACK_S old (a pause of the stream, or stages that far behind): then as
        without wait_s (the newest frame, prepared in the request if no stage is on it). Raises TimeoutError
        when the worker does not finish the frame within timeout_s,
        WorkerClosed."""
        now = self._clock()
        with self._cond:
            newest = self.submitted
            if newest == 0:
                return None
            done = self._done
            if done is not None and (done.seq == newest or now - done.submitted_s <= self.max_age_s):
                return done
            if done is not None and wait_s is not None:
                self._cond.wait_for(lambda: self._closed or self._done.seq >= newest, wait_s)
                if self._closed:
                    raise WorkerClosed("the perception worker is closed")
                if (self._done.seq >= newest
                        or self._clock() - self._done.submitted_s <= self.max_age_s + STALE_FALLBACK_S):
                    return self._done
                # The newest prepared frame is from before a pause of the stream: the newest one (below).
            waiting = [index for index, item in enumerate(self._inbox) if item is not None and item.seq == newest]
            if waiting:
                first = waiting[0]
                claimed, self._inbox[first] = self._inbox[first], None
                self._claimed = claimed.seq
            else:       # a stage (or another request) is on it
                if not self._cond.wait_for(lambda: self._closed or (self._done is not None
                                                                    and self._done.seq >= newest), timeout_s):
                    raise TimeoutError(f"the latest frame was not perceived within {timeout_s:.0f} s")
                if self._done is None or self._done.seq < newest:
                    raise WorkerClosed("the perception worker is closed")
                return self._done
        with self.priority():
            return self._prepare_from(first, claimed, _no_checkpoint)

    @contextlib.contextmanager
    def priority(self):
        """While held, the stage threads wait at their checkpoints."""
        with self._cond:
            self._priority += 1
        try:
            yield
        finally:
            with self._cond:
                self._priority -= 1
                self._cond.notify_all()

    def close(self, timeout_s: float = 5.0) -> None:
        with self._cond:
            self._closed = True
            self._cond.notify_all()
        for thread in self._threads:
            if threading.current_thread() is not thread:
                thread.join(timeout_s)

    @property
    def done(self) -> WorkerResult | None:
        """The newest prepared frame (no waiting, no freshness rule)."""
        with self._cond:
            return self._done

    # --- stages ----------------------------------------------------------------------------------
    def _checkpoint(self, index: int) -> None:
        with self._cond:
            paused = self._priority > 0
            self._cond.wait_for(lambda: self._closed or self._priority == 0)
            if self._closed:
                raise WorkerClosed("the perception worker is closed")
            item = self._in_flight[index]
            if max(self._claimed, self._done.seq if self._done is not None else 0) > item.seq:
                raise _Superseded
            if paused and self.submitted > item.seq and self._clock() - item.submitted_s > self.max_age_s:
                raise _Superseded

    def _stage(self, index: int, item: _Item, checkpoint) -> _Item:
        """Stage `index` on item (an error passes through untouched)."""
        if item.error is not None:
            return item
        try:
            return dataclasses.replace(item, value=self._stages[index](item.value, checkpoint))
        except (_Superseded, WorkerClosed):
            raise
        except ValueError as exc:
            return dataclasses.replace(item, value=None, error=exc)
        except Exception as exc:  # noqa: BLE001 - the worker and the requests must go on
            if self._on_error is not None:
                self._on_error(item.frame, exc)
            return dataclasses.replace(item, value=None, error=RuntimeError(f"internal error: {exc!r}"))

    def _prepare_from(self, first: int, item: _Item, checkpoint) -> WorkerResult:
        """Stages first.. on item, then stored as the newest prepared frame (unless a newer one is)."""
        for index in range(first, len(self._stages)):
            item = self._stage(index, item, checkpoint)
        prepared = WorkerResult(item.seq, item.frame, item.submitted_s, item.value, item.error)
        with self._cond:
            self.prepared += 1
            if self._done is None or item.seq > self._done.seq:
                self._done = prepared
            self._cond.notify_all()
        return prepared

    def _run(self, index: int) -> None:
        last = index == len(self._stages) - 1
        checkpoint = functools.partial(self._checkpoint, index)
        while True:
            with self._cond:
                self._cond.wait_for(lambda: self._closed or (self._inbox[index] is not None and self._priority == 0))
                if self._closed:
                    return
                item, self._inbox[index] = self._inbox[index], None
                self._in_flight[index] = item
            started_s = time.monotonic()
            try:
                if last:
                    prepared = self._prepare_from(index, item, checkpoint)
                    if self._on_prepared is not None:
                        self._on_prepared(prepared, checkpoint)
                else:
                    item = self._stage(index, item, checkpoint)
                    with self._cond:
                        self._put(index + 1, item)
            except _Superseded:
                with self._cond:
                    self.superseded += 1
            except WorkerClosed:
                return
            except Exception as exc:  # noqa: BLE001 - on_prepared failed: keep perceiving
                if self._on_error is not None:
                    self._on_error(item.frame, exc)
            finally:
                with self._cond:
                    self._in_flight[index] = None
                    self._cond.notify_all()
            self._rest(index, time.monotonic() - started_s)

    def _rest(self, index: int, busy_s: float) -> None:
        """After a frame: rest in proportion to the average time a frame takes (max_busy_fraction); close ends
        the rest."""
        average = self._busy_average_s[index]
        average = busy_s if average is None else average + BUSY_AVERAGE_WEIGHT * (busy_s - average)
        self._busy_average_s[index] = average
        rest_s = min(average * self._rest_per_busy, MAX_REST_S)
        if rest_s <= 0.0:
            return
        with self._cond:
            self._cond.wait_for(lambda: self._closed, rest_s)
            self.rested_s += rest_s


class RecentValues:
    """The values noted within the last window_s seconds (e.g. the top_k values requests asked for, so the
    worker can make those searches on arrival). Thread-safe; window_s 0 remembers nothing."""

    def __init__(self, window_s: float, clock=time.monotonic):
        if window_s < 0:
            raise ValueError(f"window_s must be >= 0, got {window_s}")
        self.window_s = float(window_s)
        self._clock = clock
        self._lock = threading.Lock()
        self._last_s = {}            # value -> when it was last noted

    def note(self, value) -> None:
        if self.window_s > 0:
            with self._lock:
                self._last_s[value] = self._clock()

    def recent(self) -> set:
        now = self._clock()
        with self._lock:
            for value in [v for v, t in self._last_s.items() if now - t > self.window_s]:
                del self._last_s[value]
            return set(self._last_s)
