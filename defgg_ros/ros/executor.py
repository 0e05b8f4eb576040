"""A MultiThreadedExecutor that queues each task at most once.

rclpy 7.1.6's MultiThreadedExecutor yields every task that is not yet running on every pass of
its wait loop and submits it to its thread pool again. A task already waiting in the pool's queue
is therefore queued again and again: on an idle 2-core VM the main thread loops fast enough that
the queue grew to thousands of copies of the same two tasks (3367, seen with one-off instrumentation
of rclpy's executor), and a 100 Hz timer and its subscription then fired 29-756 times in 10 s
instead of 1000 in five of six runs (bench/bench_executor_jitter.py).
A busy machine slows the spinning thread and hides it. In the cell this was a driver "silent" for
over a second and gripper results arriving 10 s late.

Worse, the spinning thread can starve the pool. While a subscription's handler waits in the
queue, the subscription is left out of the wait set but its QoS event handlers are not, and Fast
DDS then returns from every wait at once with nothing ready (37 000 empty waits in 5 s, same
instrumentation).
The spinning thread loops in Python, holding the GIL, and the queued handler that would end the
loop does not get to run.

This executor keeps the set of tasks that are queued or running and submits a task only when it is
in neither; when the wait loop offers a task that is still in flight, the spinning thread blocks
until some task finishes (at most IN_FLIGHT_WAIT_S), which hands the GIL to the workers.
"""
import sys
import threading
import traceback

from rclpy.executors import (
    ConditionReachedException,
    ExternalShutdownException,
    MultiThreadedExecutor,
    ShutdownException,
    TimeoutException,
)

# Long enough to let a worker take the GIL and finish a callback, short enough that a coroutine
# polled by the wait loop (an action's execute callback awaiting a future) is resumed promptly.
IN_FLIGHT_WAIT_S = 0.005
_NOTHING_TO_RUN = (ExternalShutdownException, ShutdownException, TimeoutException, ConditionReachedException)


class ThreadedExecutor(MultiThreadedExecutor):
    """rclpy's MultiThreadedExecutor without duplicate submissions of one task."""

    def __init__(self, num_threads=None, *, context=None):
        super().__init__(num_threads, context=context)
        self._in_flight = set()
        self._in_flight_changed = threading.Condition()

    def _spin_once_impl(self, timeout_sec=None, wait_condition=lambda: False):
        try:
            handler, _entity, _node = self.wait_for_ready_callbacks(timeout_sec, None, wait_condition)
        except _NOTHING_TO_RUN:
            return
        with self._in_flight_changed:
            if handler in self._in_flight:
                self._in_flight_changed.wait(IN_FLIGHT_WAIT_S)
                return
            self._in_flight.add(handler)
        self._executor.submit(self._run, handler)
        # The handler is an rclpy Task: it keeps what its callback raised (Task.__call__ stores the exception and
        # returns), so the Task, not the pool's future, is what to ask, as rclpy's own executor does. Asking the
        # pool's future re-raised nothing: a callback's exception was lost and the node spun on (run_node's stop
        # and exit 1 on a callback's exception never came for a node with more than one thread).
        self._futures.append(handler)
        for future in self._futures[:]:
            if future.done():
                self._futures.remove(future)
                future.result()  # re-raise what a callback raised, as rclpy does

    def _run(self, handler):
        try:
            handler()
        finally:
            with self._in_flight_changed:
                self._in_flight.discard(handler)
                self._in_flight_changed.notify_all()


class SpinThread:
    """executor.spin() in a daemon thread for a tool (recorder, replayer) that waits on futures meanwhile. A
    callback's exception ends spin(); unwatched, the thread died and every later wait ran into its timeout with
    nothing said. Here it is printed with its traceback, kept in `errors`, and spinning goes on;
    `raise_if_failed()` turns it into the tool's error."""

    def __init__(self, executor):
        self.executor, self.errors = executor, []
        self._thread = threading.Thread(target=self._run, daemon=True)
        self._thread.start()

    def _run(self) -> None:
        while True:
            try:
                self.executor.spin()
                return
            except Exception as error:  # noqa: BLE001 - kept and reported; the tool decides
                self.errors.append(error)
                traceback.print_exc(file=sys.stderr)

    def raise_if_failed(self) -> None:
        if self.errors:
            raise RuntimeError(f"a callback raised {self.errors[0]!r} ({len(self.errors)} in all; "
                               "tracebacks above)")

    def join(self, timeout_s: float) -> None:
        self._thread.join(timeout=timeout_s)
