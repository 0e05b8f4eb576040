"""Perception of the cell in plain numpy/OpenCV (no rclpy), used by the ROS nodes.

- depth.py: 16UC1 millimetres / 32FC1 metres -> float32 metres (NaN = invalid),
  with a unit plausibility check (metres sent as 16UC1, millimetres as 32FC1).
- geometry.py: quaternions, 4x4 transforms `aTb`, the top-down grasp pose in
  the camera frame, camera matrix checks.
- segmentation.py: table removal (RANSAC + least-squares plane, or an
  empty-scene capture) and object labels (connected components between a
  min and max height above the table, min area).
- stiffness_assignment.py: ObjectStiffness-like entries (ROI, region_only)
  -> per-pixel Young's modulus image; plausibility checks of moduli.
- stiffness_segmenter.py: the stiffness entries' parameter form (objects_json)
  and the default modulus; the segmentation node (the only perceiver) assigns
  them (planning/perceived_frame.py).
- tabletop.py: the tabletop perception the segmentation node runs.
- grasp_planning.py: top_k rules, the depth-sized quality image, finger boxes
  for markers.
- sync.py: StampSynchronizer, exact-stamp matching of a few streams.
- synthetic_scene.py: analytic depth images of boxes/cylinders on a
  (tilted) table, for tests and benchmarks.
"""
