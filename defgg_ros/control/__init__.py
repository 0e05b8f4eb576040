"""Motion for the pick-and-place executor: pure Python/numpy, no rclpy.

- `kinematics`: Pinocchio model of PyBullet's panda.urdf (arm joints, TCP
  frame), FK, damped-least-squares IK with restarts (`IKError`), workspace.
- `trajectories`: Ruckig joint motions, via-point transfers, straight TCP
  lines, jerk-limited stops; `check_trajectory` verifies every sample.
- `gripper_rule`: grasp force and closing window from Young's modulus.
- `pick_place` (+ `sequence_types`): the sequence as a state machine fed
  with events and clocks; `defgg_ros.nodes.executor_node` is its ROS adapter.
- `poses`: 4x4 transforms, quaternions, the top-down grasp pose.
"""
