"""The one `main()` body of every node: spin, stop cleanly, exit 2 on bad start-up input."""
import gc
import signal
import sys
import threading

import rclpy
from rclpy.executors import ExternalShutdownException, SingleThreadedExecutor
from rclpy.signals import SignalHandlerOptions

from defgg_ros.ros.executor import ThreadedExecutor
from defgg_ros.ros.launcher import watch_supervisor
from defgg_ros.ros.transport import use_large_message_transport

# How often a node that stops its hardware before exiting looks for SIGINT/SIGTERM while spinning (s): Python runs
# signal handlers only between bytecodes, and the executor's wait may block that long when nothing arrives.
SIGNAL_POLL_S = 0.02


def run_node(name: str, make_node, startup_errors=(ValueError, OSError), threads: int = 1, args=None,
             stops_hardware: bool = False) -> None:
    """Create the node with `make_node()` and spin it until Ctrl-C or shutdown.

    A bad parameter or file while the node is being built (`startup_errors`)
    prints one line naming the problem and exits with code 2; the same error
    raised while running is a bug and keeps its traceback. `threads` > 1
    spins a ThreadedExecutor (nodes with reentrant callback groups).

    stops_hardware: the node commands hardware that runs apart (the executor: the arm's controller lives in
    another process) and must stop it before anything is torn down. rclpy's own SIGINT/SIGTERM handler shuts
    the context down at once, after which nothing can be sent; so this node takes the signals itself, and on
    a signal or an exception raised in a callback calls `node.stop_for_exit(spin_once)` while its DDS
    participant still runs (spin_once(timeout_s) keeps serving its callbacks), then tears down. A stop it
    could not confirm exits 1 (stop_for_exit's reason on stderr); an exception re-raised exits 1 too.

    Before rclpy starts its DDS participant, the process takes the cell's
    Fast DDS profile (defgg_ros/ros/fastdds_profile.xml: 32 MB
    shared-memory segments, 4 MB UDP buffers) unless the caller set one.
    The profile belongs to the node, not to a launcher: a node started by
    `ros2 run`, a launch file or a console script must receive camera-sized
    messages with large buffers on its side even when the camera driver
    runs with Fast DDS's defaults (bench/bench_transport.py: a best-effort
    reader of a default 1280x720 publisher at 30 Hz got 3-11 of 30 frames,
    with or without the profile on its side; the reliable reader that
    qos.SensorSubscription picks for such a publisher gets 30 of 30). The
    profile matters for the cell's own camera-sized messages between its
    processes (docs/sessions.md).

    A node started by a NodeProcess (the bringup, the replays, the tests) stops with SIGTERM when the
    process that started it dies without stopping it (defgg_ros/ros/launcher.py, watch_supervisor).
    """
    use_large_message_transport()
    if stops_hardware:
        rclpy.init(args=args, signal_handler_options=SignalHandlerOptions.NO)
        stop_requested = _take_stop_signals()
    else:
        rclpy.init(args=args)
    watch_supervisor(name)   # started by a bringup that was then killed: stop, do not run on orphaned
    node = None
    try:
        node = make_node()
        # Everything made at start-up (torch, the model, numpy, rclpy) lives for the whole run: moved out of
        # the cyclic collector's reach, whose full collections otherwise walk it again and again (4 % of the
        # inference node's CPU at 30 Hz in a perf profile, 2026-11-27).
        gc.collect()
        gc.freeze()
        if stops_hardware:
            _spin_then_stop(name, node, _executor_for(threads, node), stop_requested)
        elif threads > 1:
            _executor_for(threads, node).spin()
        else:
            rclpy.spin(node)
    except (KeyboardInterrupt, ExternalShutdownException):
        pass
    except Exception as exc:
        if not rclpy.ok():
            # SIGINT/SIGTERM while the node was being built: rclpy's handler shut the context down under
            # the constructor, which then fails ("context is not valid"). A requested stop, not a bug.
            return
        if node is not None or not isinstance(exc, startup_errors):
            raise
        print(f"{name}: {exc}", file=sys.stderr, flush=True)
        raise SystemExit(2) from None
    finally:
        if node is not None:
            node.destroy_node()
        rclpy.try_shutdown()


def _executor_for(threads: int, node):
    executor = ThreadedExecutor(num_threads=threads) if threads > 1 else SingleThreadedExecutor()
    executor.add_node(node)
    return executor


def _take_stop_signals() -> threading.Event:
    """SIGINT and SIGTERM set the returned event (the context stays up; see run_node)."""
    stop_requested = threading.Event()
    for sig in (signal.SIGINT, signal.SIGTERM):
        signal.signal(sig, lambda *_: stop_requested.set())
    return stop_requested


def _spin_then_stop(name: str, node, executor, stop_requested: threading.Event) -> None:
    """Spin until a stop signal or a callback's exception; then the node's stop_for_exit, still spinning."""
    def spin_once(timeout_s: float) -> None:
        executor.spin_once(timeout_sec=timeout_s)

    error = None
    try:
        while not stop_requested.is_set():
            spin_once(SIGNAL_POLL_S)
    except Exception as exc:  # noqa: BLE001 - stop the hardware first, then re-raise it
        error = exc
        print(f"{name}: {exc!r} raised in a callback: stopping", file=sys.stderr, flush=True)
    failure = _stop_for_exit(node, spin_once)
    if error is not None:
        raise error
    if failure:
        print(f"{name}: {failure}", file=sys.stderr, flush=True)
        raise SystemExit(1)


def _stop_for_exit(node, spin_once) -> str:
    """The node's stop before exit ('' = confirmed); a callback raising while it waits must not skip it."""
    for _ in range(3):
        try:
            return node.stop_for_exit(spin_once)
        except Exception as exc:  # noqa: BLE001 - try again: the stop is what matters now
            print(f"stop_for_exit: {exc!r} raised while stopping; trying again", file=sys.stderr, flush=True)
    return "could not confirm the stop: callbacks kept raising while stopping"
