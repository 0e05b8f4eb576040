"""The table frame (perception/table_pose.py): a camera pose estimated from the frame when the configured one
finds no table. On the generated tilted and overhead scenes, given the wrong (default top-down) pose, the
estimate must put the table flat at table_z_m, differ from the true pose only by a motion in the table's plane,
and give the same objects as the true pose."""
import math

import numpy as np
import pytest

from defgg_ros.perception import tabletop_scenes as ts
from defgg_ros.perception.table_pose import (
    PoseFromTable,
    camera_points,
    dominant_plane,
    pose_fits_plane,
    table_frame_pose,
)
from defgg_ros.perception.tabletop import TabletopConfig, TabletopError, perceive

pytestmark = pytest.mark.unit

DEFAULT_POSE = np.array([[1.0, 0, 0, 0.5], [0, -1.0, 0, 0.0], [0, 0, -1.0, 0.4], [0, 0, 0, 1.0]])  # top-down 0.40 m


def _scenes():
    yield "tilted 1280x720", ts.render(ts.cluttered_table(1280, 720), seed=3)
    yield "tilted 640x480", ts.render(ts.cluttered_table(640, 480), seed=4)
    can = next(o for o in ts.cluttered_objects() if o.name == "can")
    yield "overhead 0.55 m", ts.render(ts.overhead_single(can), seed=5)


SCENES = dict(_scenes())


@pytest.mark.parametrize("name", list(SCENES))
def test_the_table_frame_is_the_true_pose_moved_in_the_tables_plane(name):
    frame = SCENES[name]
    config = TabletopConfig()
    normal, offset, share = dominant_plane(camera_points(frame.depth_m, frame.camera_k))
    assert share > 0.4
    assert pose_fits_plane(frame.base_T_camera, normal, offset, config)
    assert not pose_fits_plane(DEFAULT_POSE, normal, offset, config)
    estimated = table_frame_pose(frame.depth_m, frame.camera_k, config)
    # true base -> estimated base: a turn about z and a shift in x, y (the table is z = 0 in both).
    motion = estimated @ np.linalg.inv(frame.base_T_camera)
    assert math.degrees(math.acos(min(1.0, motion[2, 2]))) < 1.0, motion
    assert abs(motion[2, 3]) < 0.005, motion
    view = perceive(frame.depth_m, frame.camera_k, estimated, config)
    truth = perceive(frame.depth_m, frame.camera_k, frame.base_T_camera, config)
    assert abs(view.table_z_at(0.5, 0.0)) < 0.005
    assert len(view.object_ids) == len(truth.object_ids) >= 1
    # The same pixels are objects (up to the edges of the workspace box, which moved with the frame).
    agree = np.mean((view.labels > 0) == (truth.labels > 0))
    assert agree > 0.98, agree


def test_pose_from_table_keeps_a_working_pose_and_its_estimate():
    frame = SCENES["tilted 640x480"]
    poses = PoseFromTable(recheck_s=0.0)
    pose, estimated = poses.pose_for(frame.depth_m, frame.camera_k, frame.base_T_camera)
    assert not estimated and np.array_equal(pose, frame.base_T_camera)     # the configured pose finds the table
    pose, estimated = poses.pose_for(frame.depth_m, frame.camera_k, DEFAULT_POSE)
    assert estimated
    assert len(perceive(frame.depth_m, frame.camera_k, pose, poses.config).object_ids) >= 6
    again, estimated = poses.pose_for(SCENES["tilted 640x480"].depth_m, frame.camera_k, DEFAULT_POSE)
    assert estimated and again is pose                                       # kept, not estimated per frame


def test_no_plane_facing_the_camera_is_a_clear_error():
    rng = np.random.default_rng(0)
    k = ts.realsense_k(640, 480)
    scattered = (0.3 + 1.5 * rng.random((480, 640))).astype(np.float32)    # no surface at all
    with pytest.raises(TabletopError, match="no table in view"):
        table_frame_pose(scattered, k)
    with pytest.raises(TabletopError, match="too few depth returns"):
        table_frame_pose(np.full((480, 640), np.nan, np.float32), k)


def test_the_decision_is_reused_within_recheck_s_for_the_same_configured_pose():
    now = [0.0]
    poses = PoseFromTable(recheck_s=1.0, clock=lambda: now[0])
    frame = SCENES["tilted 640x480"]
    assert poses.pose_for(frame.depth_m, frame.camera_k, DEFAULT_POSE)[1]
    # Within the second the frame is not looked at again (a frame without any plane would raise).
    empty = np.full(frame.depth_m.shape, np.nan, np.float32)
    now[0] = 0.5
    assert poses.pose_for(empty, frame.camera_k, DEFAULT_POSE)[1]
    assert not poses.pose_for(frame.depth_m, frame.camera_k, frame.base_T_camera)[1]    # another pose: checked
    now[0] = 2.0
    with pytest.raises(TabletopError):
        poses.pose_for(empty, frame.camera_k, frame.base_T_camera)
