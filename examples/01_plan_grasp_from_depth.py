"""Plan a grasp from a depth image file with the shipped Def-GG-CNN: no ROS, no simulator.

    .venv/bin/python examples/01_plan_grasp_from_depth.py --make-sample /tmp/depth.png   # a generated frame
    .venv/bin/python examples/01_plan_grasp_from_depth.py /tmp/depth.png --modulus-pa 2e5

The depth file is a 16-bit PNG in millimetres (what a RealSense's 16UC1 topic holds; 0 = no return) or a .npy
array in metres. The camera looks down at the table; its intrinsics default to a D435's 640x480 mode. Every pixel
gets the same Young's modulus here; the cell's segmentation node gives each object its own (docs/perception.md).
"""
import argparse
from pathlib import Path

import cv2
import numpy as np

from defgg_ros.model.inference import GraspPredictor
from defgg_ros.perception import tabletop_scenes

REPO = Path(__file__).resolve().parents[1]


def read_depth_m(path: Path) -> np.ndarray:
    if path.suffix == ".npy":
        return np.load(path).astype(np.float32)
    raw_mm = cv2.imread(str(path), cv2.IMREAD_UNCHANGED)
    if raw_mm is None or raw_mm.dtype != np.uint16:
        raise SystemExit(f"{path}: not a 16-bit PNG (depth in mm)")
    return np.where(raw_mm > 0, raw_mm / 1000.0, np.nan).astype(np.float32)   # 0 mm = no return


def write_sample(path: Path):
    """A 5 x 4 x 6 cm box under an overhead camera 0.55 m up, rendered with a D435's noise."""
    box = tabletop_scenes.Box(center_xy_m=(0.5, 0.0), size_m=(0.05, 0.04, 0.06))
    frame = tabletop_scenes.render(tabletop_scenes.overhead_single(box), seed=0)
    depth_mm = np.nan_to_num(frame.depth_m * 1000.0, nan=0.0).round().astype(np.uint16)
    cv2.imwrite(str(path), depth_mm)
    print(f"wrote {path} ({depth_mm.shape[1]}x{depth_mm.shape[0]}, a box 0.49 m below the camera)")


def main():
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("depth", type=Path, help="16-bit PNG in mm or .npy in m")
    parser.add_argument("--make-sample", action="store_true", help="write a generated frame to DEPTH and exit")
    parser.add_argument("--modulus-pa", type=float, default=2e5, help="Young's modulus of every pixel (Pa)")
    parser.add_argument("--fx", type=float, default=None, help="focal length in px (default: the D435's)")
    parser.add_argument("--top-k", type=int, default=1,
                        help="grasps to print (without an object mask lower ranks may lie on the table)")
    parser.add_argument("--weights", type=Path, default=REPO / "models" / "defgg_cnn.pt")
    args = parser.parse_args()
    if args.make_sample:
        return write_sample(args.depth)

    depth_m = read_depth_m(args.depth)
    height_px, width_px = depth_m.shape
    camera_k = tabletop_scenes.realsense_k(width_px, height_px, args.fx)
    predictor = GraspPredictor.from_checkpoint(args.weights, num_threads=1)
    moduli_pa = np.full(depth_m.shape, args.modulus_pa, dtype=np.float32)
    prediction = predictor.predict(depth_m, moduli_pa, camera_k, top_k=args.top_k)
    for rank, grasp in enumerate(prediction.candidates, start=1):
        x, y, z = grasp.position_camera_m
        print(f"grasp {rank}: pixel ({grasp.center_u_px:.0f}, {grasp.center_v_px:.0f}), "
              f"angle {np.degrees(grasp.angle_rad):.1f} deg, opening {grasp.width_m * 1000:.1f} mm, "
              f"quality {grasp.quality:.2f}, camera frame ({x:.3f}, {y:.3f}, {z:.3f}) m")


if __name__ == "__main__":
    main()
