"""Perception on arrival: a worker thread prepares each frame as it arrives, requests take the result (no rclpy).

    worker = LatestFrameWorker(prepare, max_age_s=0.3)   # prepare(frame, checkpoint) -> result; ValueError: bad
    worker.submit(frame)                     # from the subscription callback, every synchronised frame
    done = worker.latest()                   # in a request: a PreparedFrame (None: no frame yet)
    with worker.priority():                  # the request's own work; the worker waits at its checkpoints
        answer(done.value())

Rules (docs/perception.md, "Latency"):
- Only the newest unprocessed frame is kept: a frame submitted while another waits replaces it (dropped).
- `latest()` answers from the newest prepared frame when it is the newest submitted frame or was
  submitted at most max_age_s before the call (clock: time.monotonic, when the frame was submitted, not its
  stamp). Otherwise from the newest submitted frame: the call waits for the worker when the worker is on it,
  else takes it from the queue and prepares it itself. So an answer never comes from a frame older than
  the newest prepared one, nor older than max_age_s while a newer frame exists.
- A frame whose preparation raised ValueError is a prepared frame too: requests get its error.
- While a request holds `priority()` the worker waits at its next checkpoint (the prepare function calls
  `checkpoint()` between its stages) and starts no new frame, so the request's work does not share the
  interpreter with it. A frame that a request prepared itself makes the worker drop the older frame it was
  on at its next checkpoint; a frame that became older than max_age_s while the worker waited is dropped
  when a newer frame waits (no request could use it any more).
"""
from __future__ import annotations

import contextlib
import threading
import time
from dataclasses import dataclass


class WorkerClosed(RuntimeError):
    """The worker was closed (the node is shutting down)."""


class _Superseded(Exception):
    """Raised at a checkpoint: a newer frame is already prepared, this one is not needed."""


@dataclass(frozen=True)
class PreparedFrame:
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


def _no_checkpoint() -> None:
    pass


class LatestFrameWorker:
    def __init__(self, prepare, max_age_s: float, on_prepared=None, name: str = "perception_on_arrival",
                 clock=time.monotonic, on_error=None):
        """prepare(frame, checkpoint) -> result. max_age_s: the freshness rule's age (module docstring).
        on_prepared(prepared, checkpoint): called in the worker thread
        after each frame it prepared is stored (e.g. publish its grasps). on_error(frame, exception): an
        unexpected (non-ValueError) exception of prepare; the frame's requests get it as their error."""
        self._prepare = prepare
        self.max_age_s = float(max_age_s)
        self._on_prepared = on_prepared
        self._on_error = on_error
        self._clock = clock
        self._cond = threading.Condition()
        self._pending = None          # (seq, frame, submitted_s) not started yet
        self._in_flight = 0           # seq the worker is preparing, 0: none
        self._in_flight_submitted_s = 0.0
        self._done = None             # the newest PreparedFrame
        self._claimed = 0             # the newest seq a request took from the queue
        self._priority = 0            # requests holding priority()
        self._closed = False
        self.submitted = 0            # frames submitted
        self.prepared = 0             # frames prepared (by the worker or by requests)
        self.dropped = 0              # frames replaced in the queue before anyone started them
        self.superseded = 0           # frames the worker stopped because a newer one was prepared
        self._thread = threading.Thread(target=self._run, name=name, daemon=True)
        self._thread.start()

    # --- producer --------------------------------------------------------------------------------
    def submit(self, frame) -> int:
        """Queue `frame` as the newest; an unstarted older frame is dropped. Returns its seq."""
        with self._cond:
            if self._closed:
                raise WorkerClosed("the perception worker is closed")
            self.submitted += 1
            if self._pending is not None:
                self.dropped += 1
            self._pending = (self.submitted, frame, self._clock())
            self._cond.notify_all()
            return self.submitted

    # --- consumer --------------------------------------------------------------------------------
    def latest(self, timeout_s: float = 30.0) -> PreparedFrame | None:
        """The prepared frame to answer a request from (module docstring); None when nothing was submitted.
        Raises TimeoutError when the worker does not finish the frame within timeout_s, WorkerClosed."""
        now = self._clock()
        with self._cond:
            newest = self.submitted
            if newest == 0:
                return None
            done = self._done
            if done is not None and (done.seq == newest or now - done.submitted_s <= self.max_age_s):
                return done
            if self._pending is not None and self._pending[0] == newest:
                claimed, self._pending = self._pending, None
                self._claimed = claimed[0]
            else:       # the worker (or another request) is on it
                if not self._cond.wait_for(lambda: self._closed or (self._done is not None
                                                                    and self._done.seq >= newest), timeout_s):
                    raise TimeoutError(f"the latest frame was not perceived within {timeout_s:.0f} s")
                if self._done is None or self._done.seq < newest:
                    raise WorkerClosed("the perception worker is closed")
                return self._done
        with self.priority():
            return self._prepare_and_store(claimed, _no_checkpoint)

    @contextlib.contextmanager
    def priority(self):
        """While held, the worker waits at its checkpoints."""
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
        if threading.current_thread() is not self._thread:
            self._thread.join(timeout_s)

    @property
    def done(self) -> PreparedFrame | None:
        """The newest prepared frame (no waiting, no freshness rule)."""
        with self._cond:
            return self._done

    # --- worker ----------------------------------------------------------------------------------
    def _checkpoint(self) -> None:
        with self._cond:
            paused = self._priority > 0
            self._cond.wait_for(lambda: self._closed or self._priority == 0)
            if self._closed:
                raise WorkerClosed("the perception worker is closed")
            if max(self._claimed, self._done.seq if self._done is not None else 0) > self._in_flight:
                raise _Superseded
            if paused and self._pending is not None \
                    and self._clock() - self._in_flight_submitted_s > self.max_age_s:
                raise _Superseded

    def _prepare_and_store(self, item, checkpoint) -> PreparedFrame:
        seq, frame, submitted_s = item
        try:
            prepared = PreparedFrame(seq, frame, submitted_s, self._prepare(frame, checkpoint))
        except (_Superseded, WorkerClosed):
            raise
        except ValueError as exc:
            prepared = PreparedFrame(seq, frame, submitted_s, error=exc)
        except Exception as exc:  # noqa: BLE001 - the worker and the requests must go on
            if self._on_error is not None:
                self._on_error(frame, exc)
            prepared = PreparedFrame(seq, frame, submitted_s, error=RuntimeError(f"internal error: {exc!r}"))
        with self._cond:
            self.prepared += 1
            if self._done is None or seq > self._done.seq:
                self._done = prepared
            self._cond.notify_all()
        return prepared

    def _run(self) -> None:
        while True:
            with self._cond:
                self._cond.wait_for(lambda: self._closed or (self._pending is not None and self._priority == 0))
                if self._closed:
                    return
                item, self._pending = self._pending, None
                self._in_flight, self._in_flight_submitted_s = item[0], item[2]
            try:
                prepared = self._prepare_and_store(item, self._checkpoint)
                if self._on_prepared is not None:
                    self._on_prepared(prepared, self._checkpoint)
            except _Superseded:
                with self._cond:
                    self.superseded += 1
            except WorkerClosed:
                return
            except Exception as exc:  # noqa: BLE001 - on_prepared failed: keep perceiving
                if self._on_error is not None:
                    self._on_error(item[1], exc)
            finally:
                with self._cond:
                    self._in_flight = 0
                    self._cond.notify_all()
