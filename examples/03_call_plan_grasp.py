"""Call the cell's PlanGrasp service from your own rclpy node and print the grasps it answers.

    .venv/bin/defgg-bringup --ros-domain 42 &                                # the simulated cell, in domain 42
    ROS_DOMAIN_ID=42 ROS_AUTOMATIC_DISCOVERY_RANGE=LOCALHOST \
        .venv/bin/python examples/03_call_plan_grasp.py                      # the cell camera's newest frame
    ... examples/03_call_plan_grasp.py --depth /tmp/depth.png                # your own frame (example 01 makes one)

An empty request plans on the newest frame the cell perceived; a request with a depth image and its camera_info
has it perceived first (the segmentation node finds the table and the objects). Grasps come best first, posed in
the robot's base frame. defgg_ros.ros.cell_client.CellClient wraps this call and the PickAndPlace action.
"""
import argparse
import time
from pathlib import Path

import cv2
import numpy as np
import rclpy
from defgg_interfaces.srv import PlanGrasp
from rclpy.node import Node
from std_msgs.msg import Header

from defgg_ros.perception.tabletop_scenes import realsense_k
from defgg_ros.ros.conversions import depth_metres_to_msg, make_camera_info
from defgg_ros.ros.service import call_idempotent


def request_for(depth_path: Path | None, top_k: int) -> PlanGrasp.Request:
    if depth_path is None:
        return PlanGrasp.Request(top_k=top_k)                       # empty: the newest perceived frame
    depth_mm = cv2.imread(str(depth_path), cv2.IMREAD_UNCHANGED)   # 16-bit PNG, millimetres, 0 = no return
    if depth_mm is None or depth_mm.dtype != np.uint16:
        raise SystemExit(f"{depth_path}: not a 16-bit PNG (depth in mm)")
    height_px, width_px = depth_mm.shape
    header = Header(frame_id="camera_depth_optical_frame")
    depth_m = np.where(depth_mm > 0, depth_mm / 1000.0, np.nan)
    return PlanGrasp.Request(depth=depth_metres_to_msg(depth_m, "16UC1", header),
                             camera_info=make_camera_info(realsense_k(width_px, height_px), width_px, height_px,
                                                          header),
                             top_k=top_k)


def main():
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--depth", type=Path, help="a 16-bit PNG depth frame (mm) to plan on instead of the camera's")
    parser.add_argument("--service", default="defgg/plan_grasp", help="the PlanGrasp service's name")
    parser.add_argument("--top-k", type=int, default=3)
    parser.add_argument("--timeout-s", type=float, default=60.0)
    args = parser.parse_args()

    rclpy.init()
    node = Node("my_grasp_client")
    try:
        client = node.create_client(PlanGrasp, args.service)
        if not client.wait_for_service(timeout_sec=args.timeout_s):
            raise SystemExit(f"{args.service} did not appear within {args.timeout_s:g} s: is the cell running "
                             "in this ROS domain (ROS_DOMAIN_ID)?")

        def spin_until(done, wait_s):                               # spin this node until done() or wait_s
            deadline = time.monotonic() + wait_s
            while not done() and time.monotonic() < deadline:
                rclpy.spin_once(node, timeout_sec=0.05)
            return done()

        # Re-sent while unanswered: Fast DDS can drop the answer to a client that has just started.
        response = call_idempotent(client, request_for(args.depth, args.top_k), args.timeout_s, "PlanGrasp",
                                   wait_until=spin_until)
        if not response.success:
            raise SystemExit(f"no grasp: {response.message}")
        for rank, grasp in enumerate(response.grasps, start=1):
            p = grasp.pose_base.pose.position
            print(f"grasp {rank}: ({p.x:.3f}, {p.y:.3f}, {p.z:.3f}) m in {grasp.pose_base.header.frame_id}, "
                  f"opening {grasp.width_m * 1000:.1f} mm, quality {grasp.quality:.2f}, "
                  f"modulus {grasp.youngs_modulus_pa:.3g} Pa")
    finally:
        node.destroy_node()
        rclpy.try_shutdown()


if __name__ == "__main__":
    main()
