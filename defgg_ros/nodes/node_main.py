"""The one `main()` body of every node: spin, stop cleanly, exit 2 on bad start-up input."""
import gc
import sys

import rclpy
from rclpy.executors import ExternalShutdownException

from defgg_ros.ros.executor import ThreadedExecutor
from defgg_ros.ros.launcher import watch_supervisor
from defgg_ros.ros.transport import use_large_message_transport


def run_node(name: str, make_node, startup_errors=(ValueError, OSError), threads: int = 1, args=None) -> None:
    """Create the node with `make_node()` and spin it until Ctrl-C or shutdown.

    A bad parameter or file while the node is being built (`startup_errors`)
    prints one line naming the problem and exits with code 2; the same error
    raised while running is a bug and keeps its traceback. `threads` > 1
    spins a ThreadedExecutor (nodes with reentrant callback groups).

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
        if threads > 1:
            executor = ThreadedExecutor(num_threads=threads)
            executor.add_node(node)
            executor.spin()
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
