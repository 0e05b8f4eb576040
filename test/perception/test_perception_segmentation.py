"""Pure segmentation and stiffness assignment on analytic depth images."""
import numpy as np
import pytest

from defgg_ros.perception import segmentation as seg
from defgg_ros.perception.depth import DepthError, depth_to_metres, metres_to_millimetres_u16
from defgg_ros.perception.stiffness_assignment import (
    InvalidYoungsModulus,
    assign_stiffness,
    check_entries_fit_image,
    make_entry,
)
from defgg_ros.perception.synthetic_scene import SceneObject, SyntheticScene, default_camera_k, render

K = default_camera_k()
# Two boxes and a cylinder at 0.4 m; left box ~ u 150..230, right cylinder ~ u 480.
SCENE = SyntheticScene(objects=(
    SceneObject(center_xy_m=(-0.15, 0.0), height_m=0.05, size_xy_m=(0.05, 0.04)),
    SceneObject(center_xy_m=(0.0, 0.08), height_m=0.03, size_xy_m=(0.06, 0.03), yaw_rad=0.5),
    SceneObject(center_xy_m=(0.16, -0.02), height_m=0.07, radius_m=0.025),
))


def _match(labels, truth):
    """Map each ground-truth object to the predicted label covering most of it."""
    mapping = {}
    for t in range(1, truth.max() + 1):
        values, counts = np.unique(labels[truth == t], return_counts=True)
        mapping[t] = int(values[np.argmax(counts)])
    return mapping


def _assert_masks_match(result, truth, min_iou=0.9):
    mapping = _match(result.labels, truth)
    assert len(result.object_ids) == truth.max() and sorted(mapping.values()) == list(result.object_ids)
    for t, label in mapping.items():
        a, b = truth == t, result.labels == label
        assert (a & b).sum() / (a | b).sum() >= min_iou, f"object {t}: IoU too low"


def test_flat_table_three_objects():
    depth, truth = render(SCENE)
    result = seg.segment_objects(depth, K)
    _assert_masks_match(result, truth)
    np.testing.assert_allclose(result.plane.offset_m, 0.4, atol=1e-3)
    np.testing.assert_allclose(result.plane.normal, [0, 0, -1], atol=1e-3)
    assert np.nanmax(result.height_m) == pytest.approx(0.07, abs=1e-3)


def test_tilted_table_is_removed_by_plane_fit():
    scene = SyntheticScene(objects=SCENE.objects, tilt_xy_rad=(0.15, -0.1))
    depth, truth = render(scene)
    # The tilt alone spans several centimetres of depth: a fixed depth cut-off would fail.
    assert np.ptp(depth[truth == 0]) > 0.05
    _assert_masks_match(seg.segment_objects(depth, K), truth)


def test_noisy_depth_with_holes():
    depth, truth = render(SCENE)
    rng = np.random.default_rng(1)
    depth = depth + rng.normal(0, 0.001, depth.shape).astype(np.float32)
    depth[rng.random(depth.shape) < 0.05] = np.nan  # 5 % dropouts
    result = seg.segment_objects(depth, K)
    _assert_masks_match(result, truth, min_iou=0.8)


def test_empty_scene_capture_background():
    depth, truth = render(SCENE)
    background, _ = render(SyntheticScene(objects=()))
    result = seg.segment_objects(depth, K, background_depth_m=background)
    assert result.plane is None
    _assert_masks_match(result, truth)


def test_min_area_and_height_thresholds():
    tiny = SceneObject(center_xy_m=(0.0, -0.1), height_m=0.05, size_xy_m=(0.005, 0.005))  # ~25 px
    flat = SceneObject(center_xy_m=(0.1, 0.1), height_m=0.002, size_xy_m=(0.05, 0.05))    # 2 mm sheet
    depth, _ = render(SyntheticScene(objects=SCENE.objects + (tiny, flat)))
    assert len(seg.segment_objects(depth, K).object_ids) == 3
    assert len(seg.segment_objects(depth, K, min_area_px=5).object_ids) == 4


def test_mm_and_m_give_the_same_segmentation():
    depth, truth = render(SCENE)
    from_mm = depth_to_metres(metres_to_millimetres_u16(depth), "16UC1")
    a = seg.segment_objects(from_mm, K)
    b = seg.segment_objects(depth_to_metres(depth, "32FC1"), K)
    assert np.mean(a.labels == b.labels) > 0.999


@pytest.mark.parametrize("depth,match", [
    (np.zeros((0, 0), np.float32), "non-empty"),
    (np.full((50, 50), np.nan, np.float32), "valid pixels"),
    (np.zeros((50, 50), np.float32), "valid pixels"),
    (np.full((50, 50), 400, np.uint16), "float metres"),
])
def test_bad_depth_raises(depth, match):
    with pytest.raises(seg.SegmentationError, match=match):
        seg.segment_objects(depth, K)


def test_metres_sent_as_millimetres_is_detected():
    depth, _ = render(SCENE)
    with pytest.raises(DepthError, match="look like metres"):
        depth_to_metres(np.rint(depth).astype(np.uint16) + 1, "16UC1")


def test_no_dominant_plane_is_refused():
    rng = np.random.default_rng(3)
    with pytest.raises(seg.SegmentationError, match="no dominant table plane"):
        seg.segment_objects((0.3 + 0.3 * rng.random((60, 80))).astype(np.float32), K)


def test_stiffness_whole_objects_default_and_region():
    depth, truth = render(SCENE)
    result = seg.segment_objects(depth, K)
    mapping = _match(result.labels, truth)
    left_u, left_v = result.centroids_px[mapping[1]]
    entries = [
        make_entry("sponge", 2e4, (int(left_u) - 5, int(left_v) - 5, 10, 10)),
        # A stiff handle: only the right half of the cylinder.
        make_entry("handle", 2e9, (int(result.centroids_px[mapping[3]][0]), 0, 640, 480), region_only=True),
    ]
    image, per_object = assign_stiffness(result.labels, result.centroids_px, entries, 2e6)
    assert image.dtype == np.float32
    assert np.all(image[result.labels == 0] == 0)
    assert np.all(image[result.labels == mapping[1]] == 2e4)
    assert np.all(image[result.labels == mapping[2]] == 2e6)
    cylinder = image[result.labels == mapping[3]]
    assert set(np.unique(cylinder)) == {np.float32(2e6), np.float32(2e9)}
    assert 0.4 < np.mean(cylinder == np.float32(2e9)) < 0.6
    assert per_object[mapping[1]] == ("sponge", 2e4) and per_object[mapping[2]][0] == "default"


def test_whole_image_entry_and_later_entries_override():
    depth, _ = render(SCENE)
    result = seg.segment_objects(depth, K)
    entries = [make_entry("all", 2e5), make_entry("all stiff", 2e9)]
    image, _ = assign_stiffness(result.labels, result.centroids_px, entries, 2e6)
    assert set(np.unique(image)) == {0.0, np.float32(2e9)}


@pytest.mark.parametrize("value", [0.0, -5.0, float("nan"), float("inf"), 1e15, 1e-3, "soft"])
def test_bad_moduli_rejected(value):
    with pytest.raises(InvalidYoungsModulus):
        make_entry("x", value)


def test_bad_roi_and_region_rules():
    with pytest.raises(ValueError, match="non-negative"):
        make_entry("x", 2e5, (-1, 0, 5, 5))
    with pytest.raises(ValueError, match="region_only"):
        make_entry("x", 2e5, region_only=True)
    with pytest.raises(ValueError, match="outside"):
        check_entries_fit_image([make_entry("x", 2e5, (700, 10, 5, 5))], 640, 480)
    with pytest.raises(InvalidYoungsModulus, match="default"):
        assign_stiffness(np.zeros((2, 2), np.uint8), {}, [], 0.0)


def test_things_too_high_above_the_table_are_the_robot_not_objects():
    hand = SceneObject(center_xy_m=(0.05, -0.12), height_m=0.30, size_xy_m=(0.06, 0.03))
    depth, truth = render(SyntheticScene(objects=SCENE.objects + (hand,)))
    result = seg.segment_objects(depth, K)
    assert len(result.object_ids) == 3 and not np.any(result.labels[truth == 4])
    assert len(seg.segment_objects(depth, K, max_height_m=0.35).object_ids) == 4
    with pytest.raises(seg.SegmentationError, match="min_height_m < max_height_m"):
        seg.segment_objects(depth, K, min_height_m=0.3, max_height_m=0.2)
