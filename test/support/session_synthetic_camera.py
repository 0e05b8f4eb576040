"""A stand-in depth camera for session tests: analytic depth frames of boxes on a table.

Publishes depth (16UC1 mm) + camera_info with the same, increasing stamps at
a fixed wall-clock rate, like realsense2_camera would (the real depth
renderer is the fake driver, which needs PyBullet and seconds per frame), and,
as a calibrated cell has it, the camera's pose on /tf_static: the hand-eye
calibration base -> camera_link, then realsense2_camera's own frames.
"""
import numpy as np
from rclpy.node import Node
from sensor_msgs.msg import CameraInfo, Image
from std_msgs.msg import Header

from defgg_ros.perception.synthetic_scene import SceneObject, SyntheticScene, render
from defgg_ros.ros import qos, realsense_frames, topics
from defgg_ros.ros.conversions import depth_metres_to_msg, make_camera_info, ns_to_stamp
from defgg_ros.ros.parameters import defaults
from defgg_ros.ros.tf import TfBroadcaster, transform_msg

SCENE = SyntheticScene(objects=(SceneObject((0.05, 0.02), 0.05, (0.05, 0.05), 0.3),
                                SceneObject((-0.08, -0.03), 0.04, (0.04, 0.07), -0.5)))


class SyntheticCamera(Node):
    def __init__(self, period_s: float = 0.2, scene: SyntheticScene = SCENE, **kwargs):
        super().__init__("synthetic_camera", **kwargs)
        depth_m, _ = render(scene)
        self._depth = depth_m
        self._k = scene.camera_k
        self._depth_pub = self.create_publisher(Image, topics.DEPTH_IMAGE, qos.SENSOR_DATA)
        self._info_pub = self.create_publisher(CameraInfo, topics.DEPTH_CAMERA_INFO, qos.SENSOR_DATA)
        self.frames = 0
        # Straight down from table_distance_m above (0.5, 0) m of the base: the synthetic scene's camera.
        base_T_optical = np.array([[1.0, 0.0, 0.0, 0.5], [0.0, -1.0, 0.0, 0.0],
                                   [0.0, 0.0, -1.0, scene.table_distance_m], [0.0, 0.0, 0.0, 1.0]])
        tree = realsense_frames.calibrated_camera_tree(defaults("segmentation_node")["base_frame"], base_T_optical)
        TfBroadcaster(self, static=True).send(*(transform_msg(*edge) for edge in tree))
        self.create_timer(period_s, self._publish)

    def _publish(self):
        self.frames += 1
        header = Header(stamp=ns_to_stamp(1_000_000_000 + self.frames * 100_000_000),
                        frame_id=topics.CAMERA_OPTICAL_FRAME)
        self._info_pub.publish(make_camera_info(self._k, self._depth.shape[1], self._depth.shape[0], header))
        self._depth_pub.publish(depth_metres_to_msg(np.asarray(self._depth), "16UC1", header))
