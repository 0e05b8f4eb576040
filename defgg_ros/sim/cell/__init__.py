"""The simulated cell: a Franka Panda with its gripper, a RealSense-like depth camera, the table, the scene's
objects and the bin in PyBullet, stepped by the fake driver node (nodes/fake_panda_driver_node.py).

``sim_cell`` (``SimCell``, ``CellSettings``) holds the world and its control period; its parts: ``camera`` (depth
rendering and noise), ``gripper`` (franka_gripper's move/grasp outcomes), ``trajectory`` (joint trajectory
tracking), ``objects`` (loading the scene's objects and the bin, the objects' material), ``soft`` (FEM objects that
sleep as static meshes until the hand comes near) and ``grid_mesh`` (box tet meshes). No rclpy, no control: the
in-process pick driver that joins the cell to control's sequence is bringup/cell_sequence.py.
"""
