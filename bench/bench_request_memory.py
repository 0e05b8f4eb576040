"""Memory per PlanGrasp request with its own images (issue 47 item 5): the image size limit bounds it.

Starts segmentation_node and grasp_inference_node in their own processes (bench_plan_grasp.start_node) and
sends PlanGrasp requests carrying depth + camera_info (the segmentation node perceives them through its
Perceive service): --calls requests at each size of --sizes (the generated cluttered table; sizes without a
RealSense mode get a D435-like focal length), then --oversized-calls 8000x6000 requests (96 MB, refused by
the image size limit). Prints, per size, each node's resident memory (VmRSS) and peak (VmHWM) after the
requests, the answers, the oversized requests' answers, and the memory 3 s after the last.
"""
import argparse
import dataclasses
import os
import time

from bench_plan_grasp import Cell, rss_mb, start_node, wait_for_node

from defgg_ros.ros.domain import pick_private_domain
from defgg_ros.ros.transport import use_large_message_transport


def peak_mb(pid: int) -> float:
    with open(f"/proc/{pid}/status") as status:
        for line in status:
            if line.startswith("VmHWM:"):
                return int(line.split()[1]) / 1024.0
    raise RuntimeError(f"no VmHWM for pid {pid}")


def request_for(width: int, height: int):
    from defgg_interfaces.srv import PlanGrasp
    from std_msgs.msg import Header

    from defgg_ros.perception import tabletop_scenes as ts
    from defgg_ros.ros.conversions import depth_metres_to_msg, make_camera_info

    scene = ts.cluttered_table(width, height)
    if (width, height) not in ts.REALSENSE_FX_PX:
        scene = dataclasses.replace(scene, fx_px=width / 2.0)
    frame = ts.render(scene, seed=1)
    header = Header(frame_id="camera_depth_optical_frame")
    return PlanGrasp.Request(depth=depth_metres_to_msg(frame.depth_m, "16UC1", header),
                             camera_info=make_camera_info(frame.camera_k, width, height, header), top_k=1), \
        frame.base_T_camera


def oversized_request():
    import numpy as np
    from defgg_interfaces.srv import PlanGrasp

    from defgg_ros.ros.conversions import make_camera_info, numpy_to_image

    k = np.array([[4000.0, 0, 4000], [0, 4000.0, 3000], [0, 0, 1]])
    return PlanGrasp.Request(depth=numpy_to_image(np.full((6000, 8000), 700, np.uint16), "16UC1"),
                             camera_info=make_camera_info(k, 8000, 6000))


def main(argv=None):
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--calls", type=int, default=5, help="requests per size")
    parser.add_argument("--sizes", default="640x480,1280x720,1280x800", help="WxH, comma-separated")
    parser.add_argument("--oversized-calls", type=int, default=3, help="8000x6000 requests (refused) at the end")
    args = parser.parse_args(argv)
    os.environ["ROS_DOMAIN_ID"] = str(pick_private_domain())
    os.environ["ROS_AUTOMATIC_DISCOVERY_RANGE"] = "LOCALHOST"
    use_large_message_transport()
    import rclpy
    from rclpy.context import Context

    from defgg_ros.ros.parameters import defaults

    sizes = [tuple(int(v) for v in s.split("x")) for s in args.sizes.split(",")]
    requests = {size: request_for(*size) for size in sizes}
    nodes = start_node(str(os.path.join(os.path.dirname(__file__), "..", "models", "defgg_cnn.pt")), 1,
                       requests[sizes[0]][1])
    context = Context()
    rclpy.init(context=context)
    try:
        cell = Cell(context, "bench_request_memory_client")
        wait_for_node(cell, nodes)
        pids = {"segmentation_node": nodes.segmentation.pid, "grasp_inference_node": nodes.inference.pid}

        def memory() -> str:
            return ", ".join(f"{name} RSS {rss_mb(pid):.0f} MB (peak {peak_mb(pid):.0f})" for name, pid in pids.items())

        print(f"limit max_image_size_px {defaults('segmentation_node')['max_image_size_px']}; at start: {memory()}")
        for size in sizes:
            answers = [cell.call(requests[size][0], timeout_s=120.0) for _ in range(args.calls)]
            ok = sum(a.success for a in answers)
            print(f"{size[0]}x{size[1]}: {ok}/{len(answers)} answered with grasps"
                  f"{'' if ok == len(answers) else ' (' + answers[-1].message[:80] + ')'}; {memory()}")
        oversized = oversized_request()
        for index in range(args.oversized_calls):
            answer = cell.call(oversized, timeout_s=120.0)
            print(f"8000x6000 #{index + 1}: success {answer.success}: {answer.message[:70]}...; {memory()}")
        settle = time.monotonic() + 3.0
        while time.monotonic() < settle:
            cell.executor.spin_once(timeout_sec=0.1)
        print(f"3 s later: {memory()}")
    finally:
        nodes.stop()
        context.try_shutdown()


if __name__ == "__main__":
    main()
