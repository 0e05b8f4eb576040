"""PlanGrasp latency through DDS next to the bare predictor call, in one run.

Starts grasp_inference_node as its own process (like the cell runs it), on a
private ROS_DOMAIN_ID, then alternates per iteration:
  bare     GraspPredictor.predict on the same 640x480 scene in this process, with the node's default
           post-processing (finger clearance at its default opening; square contacts off), so the
           ratio is what the service adds: DDS, message conversion, segmentation of the frame
  latest   PlanGrasp with an empty request (the node plans on its latest
           synchronised depth + stiffness + camera_info)
  images   PlanGrasp carrying depth (16UC1), stiffness (32FC1) and camera_info
Interleaving keeps the comparison fair while other jobs load the machine.
Prints median / p99 / max per mode and the overhead ratios (p50 and p99).
Targets (issue 5): PlanGrasp p99 <= 15 ms, overhead <= 1.3x the bare call.
"""
import argparse
import os
import sys
import time
from pathlib import Path

import numpy as np

from defgg_ros.ros.domain import pick_private_domain
from defgg_ros.ros.launcher import NodeProcess
from defgg_ros.ros.transport import FASTDDS_PROFILE_VARIABLE, use_large_message_transport

ROOT = Path(__file__).resolve().parents[1]
TARGET_P99_MS = 15.0
TARGET_OVERHEAD = 1.3


def parse_args(argv=None):
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--calls", type=int, default=300, help="calls per mode (>= 200 for a p99)")
    parser.add_argument("--warmup", type=int, default=20, help="untimed calls per mode first")
    parser.add_argument("--model", default=str(ROOT / "models" / "defgg_cnn.pt"), help="checkpoint")
    parser.add_argument("--threads", type=int, default=1, help="torch threads, bench and node alike")
    parser.add_argument("--client-executor", choices=("events", "single"), default="events",
                        help="executor of the bench's client node (events = rclpy.experimental.EventsExecutor)")
    return parser.parse_args(argv)


def scene():
    """The synthetic 640x480 test scene: two boxes and a cylinder, with moduli."""
    from defgg_ros.perception.synthetic_scene import SceneObject, SyntheticScene, default_camera_k, render

    depth_m, truth = render(SyntheticScene(objects=(
        SceneObject(center_xy_m=(-0.04, 0.02), height_m=0.05, size_xy_m=(0.05, 0.04), yaw_rad=0.3),
        SceneObject(center_xy_m=(0.06, -0.03), height_m=0.04, radius_m=0.025),
        SceneObject(center_xy_m=(0.0, -0.08), height_m=0.03, size_xy_m=(0.03, 0.06)),
    )))
    moduli = np.array([0.0, 2e4, 2e6, 2e9], dtype=np.float32)
    return depth_m, moduli[truth], truth, default_camera_k()


def start_node(model: str, threads: int) -> NodeProcess:
    """grasp_inference_node in its own process; publish_on_sync off so only PlanGrasp costs CPU."""
    cmd = [sys.executable, "-m", "defgg_ros.nodes.grasp_inference_node", "--ros-args",
           "-p", f"model_path:={model}", "-p", f"num_threads:={threads}", "-p", "publish_on_sync:=false",
           "--log-level", "warn"]
    return NodeProcess("grasp_inference_node", cmd, cwd=ROOT)


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
        from sensor_msgs.msg import CameraInfo, Image

        from defgg_ros.nodes import qos
        from defgg_ros.ros import topics

        self.node = Node(name, context=context)
        self.executor = make_executor(executor, context)
        self.executor.add_node(self.node)
        self.client = self.node.create_client(PlanGrasp, topics.PLAN_GRASP_SERVICE)
        self.pubs = [self.node.create_publisher(Image, topics.DEPTH_IMAGE, qos.SENSOR_DATA),
                     self.node.create_publisher(Image, topics.STIFFNESS_IMAGE, qos.SENSOR_DATA),
                     self.node.create_publisher(CameraInfo, topics.DEPTH_CAMERA_INFO, qos.SENSOR_DATA)]

    def call(self, request, timeout_s=30.0):
        future = self.client.call_async(request)
        self.executor.spin_until_future_complete(future, timeout_sec=timeout_s)
        if not future.done():
            raise TimeoutError("PlanGrasp did not answer")
        return future.result()


def messages(depth_m, moduli_pa, camera_k, stamp_sec=1):
    from std_msgs.msg import Header

    from defgg_ros.nodes.conversions import depth_metres_to_msg, make_camera_info, numpy_to_image

    header = Header(frame_id="camera_depth_optical_frame")
    header.stamp.sec = stamp_sec
    h, w = depth_m.shape
    return (depth_metres_to_msg(depth_m, "16UC1", header), numpy_to_image(moduli_pa, "32FC1", header),
            make_camera_info(camera_k, w, h, header))


def prime_latest_frame(cell, frame_msgs, deadline_s=60.0):
    """Publish one synchronised frame until an empty PlanGrasp request succeeds."""
    from defgg_interfaces.srv import PlanGrasp

    deadline = time.monotonic() + deadline_s
    while time.monotonic() < deadline:
        for pub, msg in zip(cell.pubs, frame_msgs):
            pub.publish(msg)
        cell.executor.spin_once(timeout_sec=0.1)
        if cell.call(PlanGrasp.Request()).success:
            return
    raise RuntimeError("the node never synchronised the published frame")


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
    os.environ["ROS_DOMAIN_ID"] = str(pick_private_domain())
    os.environ["ROS_AUTOMATIC_DISCOVERY_RANGE"] = "LOCALHOST"
    use_large_message_transport()  # the cell's Fast DDS transports, as defgg-bringup sets them
    import rclpy
    import torch
    from defgg_interfaces.srv import PlanGrasp
    from rclpy.context import Context
    from tqdm import tqdm

    from defgg_ros.model.inference import GraspPredictor

    torch.set_num_threads(args.threads)
    depth_m, moduli_pa, labels, camera_k = scene()
    predictor = GraspPredictor.from_checkpoint(args.model)
    proc = start_node(args.model, args.threads)
    context = Context()
    rclpy.init(context=context)
    try:
        cell = Cell(context, executor=args.client_executor)
        wait_for_node(cell, proc)
        frame_msgs = messages(depth_m, moduli_pa, camera_k)
        prime_latest_frame(cell, frame_msgs)
        image_request = PlanGrasp.Request(depth=frame_msgs[0], stiffness=frame_msgs[1], camera_info=frame_msgs[2])
        from defgg_ros.nodes.grasp_inference_node import PARAMETERS
        node_clearance_m = PARAMETERS["finger_clearance_opening_m"].default   # the node's default
        modes = {
            "bare predictor.predict": lambda: predictor.predict(depth_m, moduli_pa, camera_k, labels, top_k=1,
                                                                finger_clearance_opening_m=node_clearance_m),
            "PlanGrasp (latest frame)": lambda: _ok(cell.call(PlanGrasp.Request())),
            "PlanGrasp (images in request)": lambda: _ok(cell.call(image_request)),
        }
        times = {name: [] for name in modes}
        in_node = {name: [] for name in modes}  # the node's own predict time (response.inference_time_s)
        for i in tqdm(range(args.warmup + args.calls), desc="interleaved calls", unit="round", mininterval=5):
            for name, fn in modes.items():
                start = time.perf_counter()
                result = fn()
                if i >= args.warmup:
                    times[name].append(time.perf_counter() - start)
                    if hasattr(result, "inference_time_s"):
                        in_node[name].append(result.inference_time_s)
        report(times, in_node, args, predictor.runtime)
    finally:
        proc.stop()
        context.try_shutdown()


def _ok(response):
    if not response.success:
        raise RuntimeError(f"PlanGrasp failed: {response.message}")
    return response


def report(times, in_node, args, runtime):
    print(f"\nPlanGrasp latency, {args.calls} calls per mode, torch threads {args.threads}, runtime {runtime}, "
          f"client executor {args.client_executor}, "
          f"Fast DDS profile {Path(os.environ.get(FASTDDS_PROFILE_VARIABLE, 'built-in')).name}, "
          f"load average {os.getloadavg()[0]:.1f}")
    print(f"{'mode':32s} {'median ms':>10s} {'p99 ms':>8s} {'max ms':>8s}")
    bare = stats_ms(times["bare predictor.predict"])
    for name, seconds in times.items():
        median, p99, worst = stats_ms(seconds)
        print(f"{name:32s} {median:10.2f} {p99:8.2f} {worst:8.2f}")
    for name in list(times)[1:]:
        node_median, node_p99, _ = stats_ms(in_node[name])
        print(f"{name:32s} predict inside the node: median {node_median:.2f} ms, p99 {node_p99:.2f} ms")
    for name in list(times)[1:]:
        median, p99, _ = stats_ms(times[name])
        print(f"{name}: overhead vs bare {median / bare[0]:.2f}x (median), {p99 / bare[1]:.2f}x (p99); "
              f"p99 target {TARGET_P99_MS} ms {'met' if p99 <= TARGET_P99_MS else 'NOT met'}, "
              f"overhead target {TARGET_OVERHEAD}x {'met' if median / bare[0] <= TARGET_OVERHEAD else 'NOT met'}")


if __name__ == "__main__":
    main()
