"""Fresh answers under load (issue 47 item 4): PlanGrasp latency and the answer's frame age while a camera
streams 1280x720 at 30 Hz and another process keeps one of the two cores busy.

Starts segmentation_node (the only perceiver) and grasp_inference_node in their own processes on a private
ROS_DOMAIN_ID (bench_plan_grasp.start_node), a camera process streaming the generated cluttered table
(eight objects, a tilted D435, sensor noise; two noise seeds alternating, a new wall-clock stamp per frame)
at --camera-hz, reliable like realsense2_camera, and --hog processes that each spin one core at 100 %
(pure Python, holding no lock the nodes need). After --warmup s, a client asks PlanGrasp for the latest
frame every --request-period s for --seconds s and prints:
- PlanGrasp latency (request to answer) median / p99 / max; target p99 <= 50 ms;
- the answer's frame age (request time - the stamp of the frame its grasps come from) median / p99 / max;
  target p99 <= 200 ms;
- failed answers (success false) and their first message;
- each node's last /diagnostics: frames in, perceived / prepared, dropped (newest frame wins: a frame that
  arrives while one waits replaces it), its latency percentiles; and frames the camera sent;
- each node's CPU time per frame it perceived / prepared over the measured window (where the CPU goes);
- the load average and what else ran (`ps` top CPU consumers outside this bench), so the conditions are on
  record.
"""
import argparse
import multiprocessing
import os
import subprocess
import time

import numpy as np
from bench_plan_grasp import ROOT, Camera, Cell, scene, start_node, wait_for_node

from defgg_ros.ros.domain import pick_private_domain
from defgg_ros.ros.transport import use_large_message_transport

TARGET_LATENCY_P99_MS = 50.0
TARGET_AGE_P99_MS = 200.0


def parse_args(argv=None):
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--mode", default="1280x720", help="camera resolution WxH")
    parser.add_argument("--camera-hz", type=float, default=30.0, help="frames per second streamed")
    parser.add_argument("--hog", type=int, default=1, help="CPU hog processes (each keeps one core busy)")
    parser.add_argument("--seconds", type=float, default=60.0, help="measured seconds")
    parser.add_argument("--warmup", type=float, default=10.0, help="seconds of streaming before measuring")
    parser.add_argument("--request-period", type=float, default=0.1, help="seconds between PlanGrasp requests")
    parser.add_argument("--top-k", type=int, default=1, help="grasps per request")
    parser.add_argument("--model", default=str(ROOT / "models" / "defgg_cnn.pt"), help="checkpoint")
    parser.add_argument("--max-frame-age", type=float, default=None,
                        help="the inference node's max_frame_age_s (default: its schema's)")
    parser.add_argument("--perception-fraction", type=float, default=None,
                        help="the segmentation node's perception_max_core_fraction (default: its schema's)")
    parser.add_argument("--prepare-stages", type=int, default=None,
                        help="the inference node's prepare_stages (default: its schema's)")
    return parser.parse_args(argv)


def hog_main(stop) -> None:
    """One core at 100 % until stop is set."""
    x = 0
    while not stop.is_set():
        for _ in range(200_000):
            x += 1


class Hogs:
    def __init__(self, count: int):
        ctx = multiprocessing.get_context("spawn")
        self.stop = ctx.Event()
        self.processes = [ctx.Process(target=hog_main, args=(self.stop,), daemon=True) for _ in range(count)]
        for process in self.processes:
            process.start()

    def close(self):
        self.stop.set()
        for process in self.processes:
            process.join(5.0)
            if process.is_alive():
                process.terminate()


class Diagnostics:
    """The last /diagnostics status of each node, as {name: {key: value}}."""

    def __init__(self, node):
        from diagnostic_msgs.msg import DiagnosticArray

        from defgg_ros.ros.diagnostics import DIAGNOSTICS_TOPIC

        self.last = {}
        node.create_subscription(DiagnosticArray, DIAGNOSTICS_TOPIC, self._on, 10)

    def _on(self, msg):
        for status in msg.status:
            self.last[status.name.lstrip("/")] = {kv.key: kv.value for kv in status.values}


def other_load() -> str:
    """The top CPU consumers not started by this bench (their command, %CPU), for the record."""
    mine = {os.getpid()} | {int(p) for p in subprocess.run(["pgrep", "-g", str(os.getpgid(0))], capture_output=True,
                                                            text=True).stdout.split()}
    out = subprocess.run(["ps", "-eo", "pid,pcpu,args", "--sort=-pcpu"], capture_output=True, text=True).stdout
    rows = []
    for line in out.splitlines()[1:]:
        pid, cpu, command = line.split(None, 2)
        if int(pid) not in mine and float(cpu) >= 5.0:
            rows.append(f"{float(cpu):.0f}% {command[:90]}")
    return "; ".join(rows[:6]) or "nothing over 5 %"


def cpu_s(pid: int) -> float:
    """User + system CPU seconds of a process so far (all its threads)."""
    with open(f"/proc/{pid}/stat") as stat:
        fields = stat.read().rsplit(")", 1)[1].split()
    return (int(fields[11]) + int(fields[12])) / os.sysconf("SC_CLK_TCK")


def stats(values_ms) -> str:
    v = np.asarray(values_ms, float)
    return f"median {np.median(v):.1f} ms, p99 {np.percentile(v, 99):.1f} ms, max {v.max():.1f} ms"


def main(argv=None):
    args = parse_args(argv)
    width, height = (int(v) for v in args.mode.split("x"))
    os.environ["ROS_DOMAIN_ID"] = str(pick_private_domain())
    os.environ["ROS_AUTOMATIC_DISCOVERY_RANGE"] = "LOCALHOST"
    use_large_message_transport()  # the cell's Fast DDS transports, as defgg-bringup sets them
    import rclpy
    from defgg_interfaces.srv import PlanGrasp
    from rclpy.context import Context

    from defgg_ros.ros.conversions import stamp_to_ns

    print(f"before the bench: load average {os.getloadavg()[0]:.2f} on {os.cpu_count()} cores; other processes: "
          f"{other_load()}")
    frames = [scene(width, height), scene(width, height, seed=width + 1)]
    nodes = start_node(args.model, 1, frames[0][3], max_frame_age_s=args.max_frame_age,
                       prepare_stages=args.prepare_stages, perception_max_core_fraction=args.perception_fraction)
    context = Context()
    rclpy.init(context=context)
    camera = hogs = None
    try:
        cell = Cell(context, "bench_fresh_answers_client")
        diagnostics = Diagnostics(cell.node)
        wait_for_node(cell, nodes)
        camera = Camera([f[:3] for f in frames], args.camera_hz)
        hogs = Hogs(args.hog)
        deadline = time.monotonic() + args.warmup
        while time.monotonic() < deadline:
            cell.executor.spin_once(timeout_sec=0.1)
        sent_before = camera.sent.value
        pids = {"segmentation_node": nodes.segmentation.pid, "grasp_inference_node": nodes.inference.pid}
        cpu_before = {name: cpu_s(pid) for name, pid in pids.items()}
        counts_before = {name: dict(values) for name, values in diagnostics.last.items()}
        latencies_ms, ages_ms, failures = [], [], []
        start = time.monotonic()
        next_request = start
        while time.monotonic() - start < args.seconds:
            time.sleep(max(0.0, next_request - time.monotonic()))
            next_request += args.request_period
            request_ns, t0 = time.time_ns(), time.perf_counter()
            response = cell.call(PlanGrasp.Request(top_k=args.top_k))
            latencies_ms.append((time.perf_counter() - t0) * 1e3)
            if response.success:
                ages_ms.append((request_ns - stamp_to_ns(response.grasps[0].header.stamp)) / 1e6)
            else:
                failures.append(response.message)
        span = time.monotonic() - start
        sent = camera.sent.value - sent_before
        cpu = {name: cpu_s(pid) - cpu_before[name] for name, pid in pids.items()}
        counts_after = {name: dict(values) for name, values in diagnostics.last.items()}
        end = time.monotonic() + 2.5          # the nodes' next 1 Hz /diagnostics
        while time.monotonic() < end:
            cell.executor.spin_once(timeout_sec=0.1)
        load = os.getloadavg()[0]
    finally:
        if hogs is not None:
            hogs.close()
        if camera is not None:
            camera.close()
        nodes.stop()
        context.try_shutdown()
    print(f"\n{width}x{height} at {args.camera_hz:g} Hz, {args.hog} CPU hog process(es), {len(latencies_ms)} "
          f"PlanGrasp latest-frame requests every {args.request_period:g} s over {span:.0f} s, top_k {args.top_k}, "
          f"max_frame_age_s {'default' if args.max_frame_age is None else args.max_frame_age}, prepare_stages "
          f"{'default' if args.prepare_stages is None else args.prepare_stages}, perception_max_core_fraction "
          f"{'default' if args.perception_fraction is None else args.perception_fraction}; "
          f"load average {load:.2f} on {os.cpu_count()} cores")
    print(f"camera sent {sent} frames ({sent / span:.1f}/s)")
    p99 = float(np.percentile(latencies_ms, 99))
    print(f"PlanGrasp latency: {stats(latencies_ms)} (target p99 <= {TARGET_LATENCY_P99_MS:.0f} ms: "
          f"{'met' if p99 <= TARGET_LATENCY_P99_MS else 'NOT met'})")
    if ages_ms:
        age_p99 = float(np.percentile(ages_ms, 99))
        print(f"answer's frame age: {stats(ages_ms)} (target p99 <= {TARGET_AGE_P99_MS:.0f} ms: "
              f"{'met' if age_p99 <= TARGET_AGE_P99_MS else 'NOT met'})")
    print(f"failed answers: {len(failures)}" + (f" (first: {failures[0]})" if failures else ""))
    for name, values in sorted(diagnostics.last.items()):
        keys = [k for k in values if k.startswith("frames") or k.endswith("p99 ms") or k.endswith("median ms")
                or k == "camera pose source"]
        print(f"{name}: " + ", ".join(f"{k} {values[k]}" for k in keys))
        done_key = "frames perceived" if "frames perceived" in values else "frames prepared"
        if name in cpu and done_key in counts_after.get(name, {}) and done_key in counts_before.get(name, {}):
            done = int(counts_after[name][done_key]) - int(counts_before[name][done_key])
            print(f"  {name}: CPU {cpu[name]:.1f} s in the {span:.0f} s measured ({100 * cpu[name] / span:.0f} % of a "
                  f"core), {1e3 * cpu[name] / max(done, 1):.0f} ms per frame {done_key.split()[1]} ({done})")


if __name__ == "__main__":
    main()
