"""PlanGrasp latency through DDS next to the bare planner call, per resolution, in one run.

Starts segmentation_node (the only perceiver, `base_T_camera` set to the scene's camera) and
grasp_inference_node as their own processes (like the cell runs them), on a private ROS_DOMAIN_ID. Scenes: the generated
cluttered table (perception/tabletop_scenes.py: eight objects, some touching, a tilted D435 with
the robot's base in view, sensor noise) at 640x480 and 1280x720 (--modes).
A camera process streams the scene at --camera-hz (30, like the D435) for the whole run: depth
(16UC1) and camera_info, reliable like realsense2_camera, a new stamp (the wall
clock) on every frame and the noise seed alternating between two renders, so the node always has a
new frame to perceive and no answer comes from a cache of the frame before (--camera-hz 0: one frame
published once, the old bench). Per mode, alternates per iteration:
  bare     TabletopPlanner.plan on the same frame in this process (perception, network on the
           height map, feasibility), so the difference is what the services add (DDS, conversions)
  latest   PlanGrasp with an empty request (the node plans on its latest synchronised frame;
           with prepare_on_arrival, the default, it only searches a frame prepared on arrival)
  images   PlanGrasp carrying depth (16UC1) and camera_info (perceived through Perceive)
Interleaving keeps the comparison fair while other jobs load the machine.
Prints median / p99 / max per mode, the node's own planning time, the load average, the targets
(issue 26): PlanGrasp p99 <= 15 ms at 640x480, <= 33 ms at 1280x720 (30 Hz); and how many frames per
second the camera sent, the node synchronised and the node prepared (from the latest-frame answers'
messages), with the age of the frame each latest-frame answer came from (request time - its stamp).
"""
import argparse
import multiprocessing
import os
import re
import sys
import time
from pathlib import Path

import numpy as np

from defgg_ros.ros.domain import pick_private_domain
from defgg_ros.ros.launcher import NodeProcess
from defgg_ros.ros.transport import FASTDDS_PROFILE_VARIABLE, use_large_message_transport

ROOT = Path(__file__).resolve().parents[1]
TARGET_P99_MS = {(640, 480): 15.0, (848, 480): 33.0, (1280, 720): 33.0}


def parse_args(argv=None):
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--calls", type=int, default=300, help="calls per mode (>= 200 for a p99)")
    parser.add_argument("--warmup", type=int, default=20, help="untimed calls per mode first")
    parser.add_argument("--model", default=str(ROOT / "models" / "defgg_cnn.pt"), help="checkpoint")
    parser.add_argument("--threads", type=int, default=1, help="torch threads, bench and node alike")
    parser.add_argument("--client-executor", choices=("events", "single"), default="events",
                        help="executor of the bench's client node (events = rclpy.experimental.EventsExecutor)")
    parser.add_argument("--modes", default="640x480,1280x720", help="resolutions, comma-separated WxH")
    parser.add_argument("--top-k", type=int, default=1, help="grasps per request")
    parser.add_argument("--camera-hz", type=float, default=30.0, help="frames per second streamed; 0: one frame")
    parser.add_argument("--prepare-on-arrival", choices=("true", "false"), default="true",
                        help="the inference node's prepare_on_arrival parameter")
    parser.add_argument("--publish-on-sync", choices=("true", "false"), default="true",
                        help="the node's publish_on_sync parameter (the cell's: true, the best grasp of every frame "
                             "perceived is published; a top_k 1 request then reuses that frame's search)")
    parser.add_argument("--max-frame-age", type=float, default=None, help="the node's max_frame_age_s (its default)")
    parser.add_argument("--prepare-stages", type=int, default=None,
                        help="the inference node's prepare_stages (its default: 2 threads)")
    parser.add_argument("--only-latest", action="store_true",
                        help="only latest-frame requests, one per --request-period (no bare planner or image "
                             "requests in this process: the node and the camera have the machine to themselves)")
    parser.add_argument("--request-period", type=float, default=0.05,
                        help="with --only-latest: seconds from one request's start to the next")
    return parser.parse_args(argv)


def scene(width_px: int, height_px: int, seed: int | None = None):
    """The generated cluttered table at this resolution: (depth m, moduli Pa, camera K, base_T_camera)."""
    from defgg_ros.perception import tabletop_scenes as ts

    frame = ts.render(ts.cluttered_table(width_px, height_px), seed=width_px if seed is None else seed)
    # A modulus per object (2e4 .. 2e9 Pa, the paper's decades), 0 on the table and the robot.
    lut = np.zeros(256, np.float32)
    lut[1:9] = [2e4, 2e9, 2e6, 2e5, 2e7, 2e6, 2e4, 2e8]
    return frame.depth_m, lut[frame.labels], frame.camera_k, frame.base_T_camera


class PerceptionNodes:
    """segmentation_node and grasp_inference_node, each in its own process; pid, returncode() and rss are the
    inference node's (the one PlanGrasp measures), stop() stops both."""

    def __init__(self, segmentation: NodeProcess, inference: NodeProcess):
        self.segmentation, self.inference = segmentation, inference
        self.pid = inference.pid

    def returncode(self):
        return self.inference.returncode() if self.segmentation.returncode() is None else \
            self.segmentation.returncode()

    def stop(self):
        self.inference.stop()
        self.segmentation.stop()


def start_node(model: str, threads: int, base_T_camera, prepare_on_arrival: str = "true",
               publish_on_sync: str = "true", max_frame_age_s: float | None = None,
               prepare_stages: int | None = None, max_image_size_px=None,
               perception_max_core_fraction: float | None = None) -> PerceptionNodes:
    """segmentation_node (the camera pose) and grasp_inference_node in their own processes, with the cell's
    parameters unless told otherwise."""
    from defgg_ros.perception.geometry import transform_to_xyz_quaternion

    xyz, quat = transform_to_xyz_quaternion(base_T_camera)
    pose = ",".join(f"{v:.9f}" for v in (*xyz, *quat))
    size = [] if max_image_size_px is None else ["-p", f"max_image_size_px:=[{max_image_size_px[0]},"
                                                 f"{max_image_size_px[1]}]"]
    fraction = [] if perception_max_core_fraction is None else [
        "-p", f"perception_max_core_fraction:={perception_max_core_fraction}"]
    segmentation = NodeProcess("segmentation_node", [
        sys.executable, "-m", "defgg_ros.nodes.segmentation_node", "--ros-args", "-p", f"base_T_camera:=[{pose}]",
        *size, *fraction, "--log-level", "warn"], cwd=ROOT)
    cmd = [sys.executable, "-m", "defgg_ros.nodes.grasp_inference_node", "--ros-args",
           "-p", f"model_path:={model}", "-p", f"num_threads:={threads}", "-p", f"publish_on_sync:={publish_on_sync}",
           "-p", f"prepare_on_arrival:={prepare_on_arrival}", *size, "--log-level", "warn"]
    if max_frame_age_s is not None:
        cmd[-2:-2] = ["-p", f"max_frame_age_s:={max_frame_age_s}"]
    if prepare_stages is not None:
        cmd[-2:-2] = ["-p", f"prepare_stages:={prepare_stages}"]
    return PerceptionNodes(segmentation, NodeProcess("grasp_inference_node", cmd, cwd=ROOT))


def rss_mb(pid: int) -> float:
    with open(f"/proc/{pid}/status") as status:
        for line in status:
            if line.startswith("VmRSS:"):
                return int(line.split()[1]) / 1024.0
    raise RuntimeError(f"no VmRSS for pid {pid}")


def make_executor(kind: str, context):
    """The client's executor. rclpy's C++ EventsExecutor answered a trivial service in ~0.8 ms median
    here where the Python SingleThreadedExecutor's spin_until_future_complete took ~20 ms under load."""
    if kind == "events":
        from rclpy.experimental import EventsExecutor

        return EventsExecutor(context=context)
    from rclpy.executors import SingleThreadedExecutor

    return SingleThreadedExecutor(context=context)


class Cell:
    """Client side: a node with a PlanGrasp client and camera publishers."""

    def __init__(self, context, name="bench_plan_grasp_client", executor="events"):
        from defgg_interfaces.srv import PlanGrasp
        from rclpy.node import Node

        from defgg_ros.ros import topics

        self.node = Node(name, context=context)
        self.executor = make_executor(executor, context)
        self.executor.add_node(self.node)
        self.client = self.node.create_client(PlanGrasp, topics.PLAN_GRASP_SERVICE)
        self._pubs = None

    @property
    def pubs(self):
        """Camera publishers of this process, made when first used (--camera-hz 0 only): while they exist,
        the node's camera readers see a best-effort publisher beside the camera process's reliable one and
        subscribe best effort (ros/qos.py), which no real cell does."""
        from sensor_msgs.msg import CameraInfo, Image

        from defgg_ros.ros import qos, topics

        if self._pubs is None:
            self._pubs = [self.node.create_publisher(Image, topics.DEPTH_IMAGE, qos.SENSOR_DATA),
                          self.node.create_publisher(CameraInfo, topics.DEPTH_CAMERA_INFO, qos.SENSOR_DATA)]
        return self._pubs

    def call(self, request, timeout_s=30.0):
        future = self.client.call_async(request)
        self.executor.spin_until_future_complete(future, timeout_sec=timeout_s)
        if not future.done():
            raise TimeoutError("PlanGrasp did not answer")
        return future.result()


def messages(depth_m, moduli_pa, camera_k, stamp_sec=1):
    """(depth 16UC1, camera_info) of a frame (moduli_pa: unused, the segmentation node assigns the moduli)."""
    from std_msgs.msg import Header

    from defgg_ros.ros.conversions import depth_metres_to_msg, make_camera_info

    header = Header(frame_id="camera_depth_optical_frame")
    header.stamp.sec = stamp_sec
    h, w = depth_m.shape
    return depth_metres_to_msg(depth_m, "16UC1", header), make_camera_info(camera_k, w, h, header)


def prime_latest_frame(cell, frame_msgs, deadline_s=60.0):
    """Until an empty PlanGrasp request succeeds: publish one synchronised frame (frame_msgs), or let the
    camera process stream (frame_msgs None)."""
    from defgg_interfaces.srv import PlanGrasp

    deadline = time.monotonic() + deadline_s
    while time.monotonic() < deadline:
        if frame_msgs is not None:
            for pub, msg in zip(cell.pubs, frame_msgs):
                pub.publish(msg)
        cell.executor.spin_once(timeout_sec=0.1)
        if cell.call(PlanGrasp.Request()).success:
            return
    raise RuntimeError("the node never synchronised a published frame")


def camera_main(renders, hz: float, stop, sent) -> None:
    """The camera process: publish renders[i % len(renders)] (depth m, moduli Pa, K) at `hz`, each frame
    stamped with the wall clock; a frame whose time has passed is skipped, as a camera does. sent: a
    shared counter of frames published."""
    import rclpy
    from rclpy.context import Context
    from rclpy.node import Node
    from sensor_msgs.msg import CameraInfo, Image

    from defgg_ros.ros import qos, topics

    context = Context()
    rclpy.init(context=context)
    try:
        node = Node("bench_camera", context=context)
        pubs = [node.create_publisher(Image, topics.DEPTH_IMAGE, qos.IMAGE_PUBLISH),
                node.create_publisher(CameraInfo, topics.DEPTH_CAMERA_INFO, qos.IMAGE_PUBLISH)]
        frames = [messages(*render) for render in renders]
        period, start, tick = 1.0 / hz, time.monotonic(), 0
        while not stop.is_set():
            tick = max(tick + 1, int((time.monotonic() - start) / period))    # late: skip, do not queue
            delay = start + tick * period - time.monotonic()
            if delay > 0:
                time.sleep(delay)
            now_ns = time.time_ns()
            for pub, msg in zip(pubs, frames[tick % len(frames)]):
                msg.header.stamp.sec, msg.header.stamp.nanosec = divmod(now_ns, 10**9)
                pub.publish(msg)
            with sent.get_lock():
                sent.value += 1
        node.destroy_node()
    finally:
        context.try_shutdown()


class Camera:
    """camera_main in its own process (spawned: a fresh interpreter, like a camera driver)."""

    def __init__(self, renders, hz: float):
        ctx = multiprocessing.get_context("spawn")
        self.stop, self.sent = ctx.Event(), ctx.Value("q", 0)
        self.process = ctx.Process(target=camera_main, args=(renders, hz, self.stop, self.sent), daemon=True)
        self.process.start()

    def close(self):
        self.stop.set()
        self.process.join(10.0)
        if self.process.is_alive():
            self.process.terminate()


PERCEIVED = re.compile(r"waited ([\d.]+) ms, searched ([\d.]+) ms; (\d+) of (\d+) synchronised frames prepared")


def wait_for_node(cell, proc, deadline_s=120.0):
    deadline = time.monotonic() + deadline_s
    while not cell.client.wait_for_service(timeout_sec=0.5):
        if proc.returncode() is not None or time.monotonic() > deadline:
            raise RuntimeError("grasp_inference_node did not come up")


def stats_ms(seconds) -> tuple:
    ms = np.asarray(seconds) * 1e3
    return float(np.median(ms)), float(np.percentile(ms, 99)), float(ms.max())


def main(argv=None):
    args = parse_args(argv)
    if args.calls < 200:
        raise SystemExit("--calls must be >= 200 for a meaningful p99")
    modes = [tuple(int(v) for v in m.split("x")) for m in args.modes.split(",")]
    os.environ["ROS_DOMAIN_ID"] = str(pick_private_domain())
    os.environ["ROS_AUTOMATIC_DISCOVERY_RANGE"] = "LOCALHOST"
    use_large_message_transport()  # the cell's Fast DDS transports, as defgg-bringup sets them
    import rclpy
    import torch
    from defgg_interfaces.srv import PlanGrasp
    from rclpy.context import Context
    from tqdm import tqdm

    from defgg_ros.model.inference import GraspPredictor
    from defgg_ros.planning.tabletop_planner import TabletopPlanner

    torch.set_num_threads(args.threads)
    scenes = {mode: scene(*mode) for mode in modes}
    base_T_camera = scenes[modes[0]][3]
    predictor = GraspPredictor.from_checkpoint(args.model)
    planner = TabletopPlanner(predictor)
    proc = start_node(args.model, args.threads, base_T_camera, args.prepare_on_arrival, args.publish_on_sync,
                      args.max_frame_age, args.prepare_stages)
    context = Context()
    rclpy.init(context=context)
    camera = None
    try:
        cell = Cell(context, executor=args.client_executor)
        wait_for_node(cell, proc)
        for stamp, (mode, (depth_m, moduli_pa, camera_k, _)) in enumerate(scenes.items(), start=1):
            frame_msgs = messages(depth_m, moduli_pa, camera_k, stamp_sec=stamp)
            if args.camera_hz > 0:     # the bench's frame and another noise seed of the scene, alternating
                other = scene(*mode, seed=mode[0] + 1)
                camera = Camera([(depth_m, moduli_pa, camera_k), other[:3]], args.camera_hz)
            prime_latest_frame(cell, None if camera else frame_msgs)
            image_request = PlanGrasp.Request(depth=frame_msgs[0], camera_info=frame_msgs[1], top_k=args.top_k)

            def bare(d=depth_m, k=camera_k):
                return planner.plan(d, k, base_T_camera, args.top_k)
            fns = {
                "bare planner (in process)": bare,
                "PlanGrasp (latest frame)": lambda: _ok(cell.call(PlanGrasp.Request(top_k=args.top_k))),
                "PlanGrasp (images in request)": lambda r=image_request: _ok(cell.call(r)),
            }
            if args.only_latest:
                fns = {name: fn for name, fn in fns.items() if name == "PlanGrasp (latest frame)"}
            times = {name: [] for name in fns}
            in_node = {name: [] for name in fns}  # the node's own planning time (response.inference_time_s)
            cpu = []   # the bare call's CPU time in this process: less sensitive to other jobs than wall time
            stream = Stream(camera)
            for i in tqdm(range(args.warmup + args.calls), desc=f"{mode[0]}x{mode[1]}", unit="round",
                          mininterval=5):
                if args.only_latest:
                    round_start = time.perf_counter()
                for name, fn in fns.items():
                    start, start_cpu, start_ns = time.perf_counter(), time.process_time(), time.time_ns()
                    result = fn()
                    if i >= args.warmup:
                        times[name].append(time.perf_counter() - start)
                        if name.startswith("bare"):
                            cpu.append(time.process_time() - start_cpu)
                        if hasattr(result, "inference_time_s"):
                            in_node[name].append(result.inference_time_s)
                        if name == "PlanGrasp (latest frame)":
                            stream.answer(result, start_ns)
                if args.only_latest:
                    time.sleep(max(0.0, round_start + args.request_period - time.perf_counter()))
            report(mode, times, in_node, args, predictor.runtime, cpu)
            stream.report()
            if camera is not None:
                camera.close()
                camera = None
    finally:
        if camera is not None:
            camera.close()
        proc.stop()
        context.try_shutdown()


class Stream:
    """Frames per second the camera sent, the node synchronised and perceived over the timed calls, and the
    age of the frame each latest-frame answer came from (request time - its stamp: the camera's wall clock)."""

    def __init__(self, camera):
        self.camera = camera
        self.first = self.last = None        # (time, camera sent, node synchronised, node perceived)
        self.ages_s, self.waits_ms, self.searches_ms = [], [], []


    def answer(self, response, request_ns):
        if self.camera is None:
            return
        from defgg_ros.ros.conversions import stamp_to_ns

        self.ages_s.append((request_ns - stamp_to_ns(response.grasps[0].header.stamp)) / 1e9)
        match = PERCEIVED.search(response.message)
        if match is None:     # prepare_on_arrival false: no counts in the answer
            return
        waited, searched, perceived, synchronised = match.groups()
        self.waits_ms.append(float(waited))
        self.searches_ms.append(float(searched))
        sample = (time.monotonic(), self.camera.sent.value, int(synchronised), int(perceived))
        self.first = self.first or sample
        self.last = sample

    def report(self):
        if self.camera is None:
            return
        ages = np.asarray(self.ages_s) * 1e3
        print(f"latest-frame answers: age of the frame used (request - stamp) median {np.median(ages):.1f} ms, "
              f"p99 {np.percentile(ages, 99):.1f} ms, max {ages.max():.1f} ms")
        if self.first is None or self.last[0] <= self.first[0]:
            print("(no preparation counts: prepare_on_arrival is off)")
            return
        span = self.last[0] - self.first[0]
        sent, synced, perceived = (b - a for a, b in zip(self.first[1:], self.last[1:]))
        print(f"camera sent {sent / span:.1f} frames/s, the node synchronised {synced / span:.1f}/s and prepared "
              f"{perceived / span:.1f}/s ({perceived / max(synced, 1):.0%} of them) over {span:.0f} s")
        print(f"inside the node per latest-frame answer: waiting for a prepared frame median "
              f"{np.median(self.waits_ms):.2f} ms (p99 {np.percentile(self.waits_ms, 99):.2f}), search median "
              f"{np.median(self.searches_ms):.2f} ms (p99 {np.percentile(self.searches_ms, 99):.2f})")


def _ok(response):
    if not response.success:
        raise RuntimeError(f"PlanGrasp failed: {response.message}")
    return response


def report(mode, times, in_node, args, runtime, cpu):
    target = TARGET_P99_MS.get(mode)
    print(f"\n{mode[0]}x{mode[1]}: PlanGrasp latency, top_k {args.top_k}, {args.calls} calls "
          f"per mode, torch threads {args.threads}, runtime {runtime}, client executor {args.client_executor}, "
          f"Fast DDS profile {Path(os.environ.get(FASTDDS_PROFILE_VARIABLE, 'built-in')).name}, camera "
          f"{args.camera_hz:g} Hz, prepare_on_arrival {args.prepare_on_arrival}, publish_on_sync "
          f"{args.publish_on_sync}, max_frame_age_s {'default' if args.max_frame_age is None else args.max_frame_age}, "
          f"prepare_stages {args.prepare_stages or 'default'}"
          f"{f', only latest-frame requests every {args.request_period:g} s' if args.only_latest else ''}, "
          f"load average {os.getloadavg()[0]:.1f} on {os.cpu_count()} cores")
    print(f"{'mode':32s} {'median ms':>10s} {'p99 ms':>8s} {'max ms':>8s}")
    for name, seconds in times.items():
        median, p99, worst = stats_ms(seconds)
        print(f"{name:32s} {median:10.2f} {p99:8.2f} {worst:8.2f}")
    if cpu:
        cpu_median, cpu_p99, _ = stats_ms(cpu)
        print(f"bare planner CPU time (process_time): median {cpu_median:.2f} ms, p99 {cpu_p99:.2f} ms")
    for name in [name for name in times if name.startswith("PlanGrasp")]:
        node_median, node_p99, _ = stats_ms(in_node[name])
        _, p99, _ = stats_ms(times[name])
        verdict = "" if target is None else f"; p99 target {target:.0f} ms {'met' if p99 <= target else 'NOT met'}"
        print(f"{name}: planning inside the node median {node_median:.2f} ms, p99 {node_p99:.2f} ms{verdict}")


if __name__ == "__main__":
    main()
