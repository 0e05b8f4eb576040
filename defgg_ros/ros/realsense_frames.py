"""realsense2_camera's TF frames, and the calibrated camera tree the simulated driver publishes.

What realsense2_camera (realsense-ros, branch ros2-master) publishes, read from its sources:
- Frame names from the `camera_name` parameter (default "camera", `src/parameters.cpp`; rs_launch.py's default too):
  `<camera_name>_link` (`base_frame_id`, default "link", prefixed with the camera name), and per stream
  `<camera_name>_<stream>_frame` and `<camera_name>_<stream>_optical_frame` (`include/base_realsense_node.h`:
  FRAME_ID, OPTICAL_FRAME_ID; `<stream>` is "depth", "color", "infra1" ...).
- `src/tfs.cpp` (calcAndAppendTransformMsgs): for each enabled stream `<camera_name>_link` -> `<stream>_frame` (the
  stream's extrinsics to the base stream, which is the depth stream: `src/base_realsense_node.cpp`
  base_stream_priority = {DEPTH}; so camera_link -> camera_depth_frame is the identity) and `<stream>_frame` ->
  `<stream>_optical_frame`, a pure rotation setRPY(-pi/2, 0, -pi/2) (ROS x forward, y left, z up -> optical x right,
  y down, z forward).
- Static: sent once on /tf_static by the camera node itself (tf2_ros::StaticBroadcasterQoS); on /tf as well only
  when `tf_publish_rate` > 0 (default 0.0, `include/constants.h` TF_PUBLISH_RATE; `publish_tf` default true).
- Nothing connects `<camera_name>_link` to the robot: the cell's hand-eye calibration publishes base -> camera_link
  (docs/real_cell.md, step 4).

Images and camera_info carry the optical frame of their stream (`<camera_name>_depth_optical_frame` for depth).
"""
import numpy as np

from defgg_ros.constants import LINK_COLOR_OFFSET_M

DEFAULT_CAMERA_NAME = "camera"

# <stream>_frame -> <stream>_optical_frame: columns are the optical axes in the stream's ROS frame
# (x right = -y, y down = -z, z forward = +x); quaternion (x, y, z, w) = (-0.5, 0.5, -0.5, 0.5) = RPY(-pi/2, 0, -pi/2).
FRAME_T_OPTICAL = np.array([[0.0, 0.0, 1.0, 0.0],
                            [-1.0, 0.0, 0.0, 0.0],
                            [0.0, -1.0, 0.0, 0.0],
                            [0.0, 0.0, 0.0, 1.0]])


def frame_ids(camera_name: str = DEFAULT_CAMERA_NAME) -> dict:
    """realsense2_camera's frame ids for `camera_name`: link, depth, depth_optical, color, color_optical."""
    if not camera_name:
        raise ValueError("camera_name must not be empty (realsense2_camera prefixes every frame with it)")
    return {"link": f"{camera_name}_link",
            "depth": f"{camera_name}_depth_frame", "depth_optical": f"{camera_name}_depth_optical_frame",
            "color": f"{camera_name}_color_frame", "color_optical": f"{camera_name}_color_optical_frame"}


def calibrated_camera_tree(base_frame: str, base_T_depth_optical, camera_name: str = DEFAULT_CAMERA_NAME,
                           with_color: bool = False) -> list:
    """[(parent, child, parent_T_child 4x4)] of a calibrated cell whose depth optical frame sits at
    base_T_depth_optical: the calibration base -> `<camera_name>_link` first, then realsense2_camera's own static
    frames (link -> depth frame identity, depth frame -> depth optical frame; with_color: the colour stream's pair,
    its extrinsics to the depth stream a D435's, LINK_COLOR_OFFSET_M along the link's axes, where the simulated
    colour camera renders from).
    """
    names = frame_ids(camera_name)
    link_T_optical = FRAME_T_OPTICAL                    # camera_link -> depth frame is the identity
    base_T_link = np.asarray(base_T_depth_optical, dtype=float) @ np.linalg.inv(link_T_optical)
    tree = [(base_frame, names["link"], base_T_link),
            (names["link"], names["depth"], np.eye(4)),
            (names["depth"], names["depth_optical"], FRAME_T_OPTICAL)]
    if with_color:
        link_T_color = np.eye(4)
        link_T_color[:3, 3] = LINK_COLOR_OFFSET_M
        tree += [(names["link"], names["color"], link_T_color),
                 (names["color"], names["color_optical"], FRAME_T_OPTICAL)]
    return tree
