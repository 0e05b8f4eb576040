"""defgg_ros/ros/tf.py: the TF tree (composition along a chain like a calibrated RealSense cell's,
inverse lookups, clear errors) and the listener over real DDS against a latched /tf_static publisher."""
import numpy as np
import pytest

from defgg_ros.ros.tf import (
    TfBroadcaster,
    TfListener,
    TransformTree,
    base_T_camera,
    matrix_from_transform,
    quaternion_from_matrix,
    transform_msg,
)


def _pose(xyz, axis, angle_rad):
    axis = np.asarray(axis, float) / np.linalg.norm(axis)
    k = np.array([[0, -axis[2], axis[1]], [axis[2], 0, -axis[0]], [-axis[1], axis[0], 0]])
    m = np.eye(4)
    m[:3, :3] = np.eye(3) + np.sin(angle_rad) * k + (1 - np.cos(angle_rad)) * k @ k
    m[:3, 3] = xyz
    return m


# A hand-eye calibration (base -> camera_link) and the RealSense driver's own static frames.
BASE_T_LINK = _pose([0.9, 0.1, 0.6], [0.2, 1.0, 0.1], 2.4)
LINK_T_DEPTH = _pose([0.0, 0.015, 0.0], [1, 0, 0], 0.0)
DEPTH_T_OPTICAL = _pose([0.0, 0.0, 0.0], [1, -1, 1], 2 * np.pi / 3)  # x right, y down, z forward


def _tree():
    tree = TransformTree()
    tree.add(transform_msg("fr3_link0", "camera_link", BASE_T_LINK), static=True)
    tree.add(transform_msg("camera_link", "camera_depth_frame", LINK_T_DEPTH), static=True)
    tree.add(transform_msg("camera_depth_frame", "camera_depth_optical_frame", DEPTH_T_OPTICAL), static=True)
    return tree


@pytest.mark.unit
def test_quaternion_round_trip():
    rng = np.random.default_rng(3)
    for _ in range(50):
        m = _pose(rng.normal(size=3), rng.normal(size=3), rng.uniform(0, np.pi))
        np.testing.assert_allclose(matrix_from_transform(transform_msg("a", "b", m).transform), m, atol=1e-12)
    assert quaternion_from_matrix(np.eye(3)) == (0.0, 0.0, 0.0, 1.0)


@pytest.mark.unit
def test_chain_and_inverse_lookups():
    tree = _tree()
    expected = BASE_T_LINK @ LINK_T_DEPTH @ DEPTH_T_OPTICAL
    np.testing.assert_allclose(tree.lookup("fr3_link0", "camera_depth_optical_frame"), expected, atol=1e-12)
    np.testing.assert_allclose(tree.lookup("camera_depth_optical_frame", "fr3_link0"), np.linalg.inv(expected),
                               atol=1e-12)
    # Between two leaves of one tree: through their common ancestor.
    tree.add(transform_msg("fr3_link0", "defgg_grasp", _pose([0.5, 0.0, 0.1], [1, 0, 0], np.pi)))
    grasp_in_camera = tree.lookup("camera_depth_optical_frame", "defgg_grasp")
    np.testing.assert_allclose(expected @ grasp_in_camera, tree.lookup("fr3_link0", "defgg_grasp"), atol=1e-12)
    # A later transform of a frame replaces the earlier one (the latest is used).
    tree.add(transform_msg("fr3_link0", "defgg_grasp", _pose([0.4, 0.0, 0.1], [1, 0, 0], np.pi)))
    assert tree.lookup("fr3_link0", "defgg_grasp")[0, 3] == pytest.approx(0.4)


@pytest.mark.unit
def test_missing_links_and_bad_transforms_are_named():
    tree = _tree()
    with pytest.raises(LookupError, match="no TF path from 'camera_depth_optical_frame' to 'panda_link0'"):
        tree.lookup("panda_link0", "camera_depth_optical_frame")
    with pytest.raises(ValueError, match="loop"):
        tree.add(transform_msg("camera_depth_optical_frame", "fr3_link0", np.eye(4)))
    bad = transform_msg("fr3_link0", "x", np.eye(4))
    bad.transform.rotation.w = 0.0
    with pytest.raises(ValueError, match="zero quaternion"):
        tree.add(bad)
    with pytest.raises(ValueError, match="two different frame ids"):
        tree.add(transform_msg("", "x", np.eye(4)))
    fallback = np.eye(4)
    matrix, origin = base_T_camera(tree, "panda_link0", "camera_depth_optical_frame", fallback)
    assert origin == "parameter" and matrix is not None and np.allclose(matrix, fallback)
    matrix, origin = base_T_camera(tree, "fr3_link0", "camera_depth_optical_frame", fallback)
    assert origin == "tf" and np.allclose(matrix, BASE_T_LINK @ LINK_T_DEPTH @ DEPTH_T_OPTICAL)


@pytest.mark.ros
def test_listener_gets_latched_static_and_dynamic_transforms(executor, spin):
    from rclpy.node import Node

    publisher = Node("tf_test_publisher", context=executor.context)
    executor.add_node(publisher)
    # Published before the listener exists: /tf_static is latched (transient local).
    TfBroadcaster(publisher, static=True).send(
        transform_msg("fr3_link0", "camera_link", BASE_T_LINK), transform_msg("camera_link", "camera_depth_frame",
                                                                               LINK_T_DEPTH),
        transform_msg("camera_depth_frame", "camera_depth_optical_frame", DEPTH_T_OPTICAL))
    listener_node = Node("tf_test_listener", context=executor.context)
    executor.add_node(listener_node)
    listener = TfListener(listener_node)

    def connected():
        try:
            listener.lookup("fr3_link0", "camera_depth_optical_frame")
            return True
        except LookupError:
            return False

    spin(executor, connected, 10.0, "the latched static transforms at a late listener")
    np.testing.assert_allclose(listener.lookup("fr3_link0", "camera_depth_optical_frame"),
                               BASE_T_LINK @ LINK_T_DEPTH @ DEPTH_T_OPTICAL, atol=1e-9)
    dynamic = TfBroadcaster(publisher)
    grasp = _pose([0.45, -0.05, 0.12], [1, 0, 0], np.pi)

    def grasp_known():
        dynamic.send(transform_msg("fr3_link0", "defgg_grasp", grasp))
        return "defgg_grasp" in listener.tree.frames()

    spin(executor, grasp_known, 10.0, "a /tf transform")
    np.testing.assert_allclose(listener.lookup("fr3_link0", "defgg_grasp"), grasp, atol=1e-9)
