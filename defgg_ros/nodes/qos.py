"""Named QoS profiles of the cell, so publishers and subscribers always match.

- SENSOR_DATA: camera streams (depth, colour, camera_info, stiffness image,
  mask, quality image). Best effort, keep last 5, volatile: a late frame is
  worthless, and a best-effort subscriber also matches a reliable publisher
  (realsense2_camera's default), so subscribe with this one.
- LATCHED: state that a late joiner must still get (stiffness assignments,
  the scene description): reliable + transient local, keep last 1 — the
  "latched topic" of ROS 1.
- STATE: robot state and results (joint states, wrench, best grasp,
  markers): reliable, keep last 10.
- COMMAND: commands (joint trajectories): reliable, keep last 1 so a stale
  command is never replayed after a newer one.
"""
from rclpy.qos import (
    DurabilityPolicy,
    HistoryPolicy,
    QoSProfile,
    ReliabilityPolicy,
    qos_profile_sensor_data,
)

SENSOR_DATA = qos_profile_sensor_data

LATCHED = QoSProfile(
    history=HistoryPolicy.KEEP_LAST,
    depth=1,
    reliability=ReliabilityPolicy.RELIABLE,
    durability=DurabilityPolicy.TRANSIENT_LOCAL,
)

STATE = QoSProfile(
    history=HistoryPolicy.KEEP_LAST,
    depth=10,
    reliability=ReliabilityPolicy.RELIABLE,
    durability=DurabilityPolicy.VOLATILE,
)

COMMAND = QoSProfile(
    history=HistoryPolicy.KEEP_LAST,
    depth=1,
    reliability=ReliabilityPolicy.RELIABLE,
    durability=DurabilityPolicy.VOLATILE,
)
