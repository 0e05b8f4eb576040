"""Tabletop perception and grasp planning on realistic generated frames (perception/tabletop_scenes.py):
a tilted D435 over a cluttered table with touching objects and the robot's base in view, at 640x480,
848x480 and 1280x720 with sensor noise; and overhead single-object frames. Checked against the
scenes' ground truth: per-object separation, the table plane, and the feasibility of every grasp."""
import math

import numpy as np
import pytest

from defgg_ros.constants import GRIPPER_MAX_WIDTH_M, PANDA_FINGER_THICKNESS_M, PANDA_FINGERTIP_BELOW_TCP_M
from defgg_ros.grasping.geometry import tcp_height_m
from defgg_ros.model.inference import GraspPredictor
from defgg_ros.perception import tabletop_scenes as ts
from defgg_ros.perception.tabletop import CELL_M, TabletopConfig, TabletopError, WorkspaceBox, perceive
from defgg_ros.planning.tabletop_grasps import image_projection, plan_tabletop_grasps

MODEL = GraspPredictor.from_checkpoint(__import__("pathlib").Path(__file__).resolve().parents[2] / "models" /
                                       "defgg_cnn.pt", num_threads=1)
# Objects of the cluttered scene a parallel gripper (80 mm) can take top-down, and those it cannot.
NOT_GRASPABLE = {"cereal box", "cup", "bottle"}    # 140+ mm flat top, 80 mm cup, 70 mm lying bottle


@pytest.fixture(scope="module", params=ts.MODES, ids=[f"{w}x{h}" for w, h in ts.MODES])
def cluttered(request):
    scene = ts.cluttered_table(*request.param)
    frame = ts.render(scene, seed=sum(request.param))
    return scene, frame, perceive(frame.depth_m, frame.camera_k, frame.base_T_camera)


def test_frames_have_the_d435_modes_and_its_artefacts(cluttered):
    scene, frame, _ = cluttered
    h, w = frame.depth_m.shape
    assert (w, h) == (scene.width_px, scene.height_px)
    assert frame.camera_k[0, 0] == ts.REALSENSE_FX_PX[(w, h)] and frame.camera_k[0, 2] == (w - 1) / 2
    valid = np.isfinite(frame.depth_m)
    holes = ~valid & np.isfinite(frame.clean_depth_m)
    assert 0.015 < holes.mean() < 0.3                     # shadows, speckle, dark and shiny dropouts
    mm = frame.depth_m[valid] * 1000
    assert np.allclose(mm, np.round(mm), atol=1e-3)      # 16UC1 millimetres
    noise = (frame.depth_m - frame.clean_depth_m)[valid & np.isfinite(frame.clean_depth_m) & (frame.labels == 0)]
    assert 0.0003 < np.median(np.abs(noise)) < 0.003     # D4xx RMS error at 0.5-0.7 m
    cup = scene.objects.index(next(o for o in scene.objects if o.material == "dark")) + 1
    assert np.mean(~valid[frame.labels == cup]) > 0.2    # missing returns on the dark cup
    # Stereo shadow: invalid pixels just left of the can's left edge (the left imager is the reference).
    can = [o.name for o in scene.objects].index("can") + 1
    rows, cols = np.nonzero(frame.labels == can)
    left = [frame.depth_m[r, max(c - 3, 0)] for r, c in zip(rows, cols) if frame.labels[r, max(c - 1, 0)] != can]
    assert np.mean(~np.isfinite(left)) > 0.3
    assert np.any(frame.labels == ts.ROBOT_LABEL)        # the robot's base and plate are in view


def test_table_plane_in_the_robot_frame_despite_the_tilt(cluttered):
    _, _, view = cluttered
    assert math.degrees(math.acos(min(1.0, view.table_normal[2]))) < 1.0
    assert abs(view.table_z_at(0.5, 0.0)) < 0.003


def test_touching_objects_come_out_separate_and_the_robot_is_not_an_object(cluttered):
    scene, frame, view = cluttered
    dominant = {}
    for index, obj in enumerate(scene.objects, start=1):
        truth = frame.labels == index
        found = view.labels[truth]
        found = found[found > 0]
        assert found.size > 0.4 * truth.sum(), f"{obj.name}: only {found.size} of {truth.sum()} pixels segmented"
        label = int(np.bincount(found).argmax())
        share = np.mean(view.labels[truth] == label)
        purity = np.mean(frame.labels[view.labels == label] == index)
        # A dark object loses ~30 % of its returns in blotches and may come out in pieces (each pure).
        least = 0.25 if obj.material == "dark" else 0.4
        assert share > least and purity > 0.8, f"{obj.name}: label {label} covers {share:.0%}, purity {purity:.0%}"
        dominant[obj.name] = label
    assert len(set(dominant.values())) == len(dominant), f"objects merged: {dominant}"
    # The pairs that touch are apart: can | cereal box, cup | cereal box, rubber block | sponge.
    for a, b in (("can", "cereal box"), ("cup", "cereal box"), ("rubber block", "sponge")):
        assert dominant[a] != dominant[b]
    assert not np.any(view.labels[frame.labels == ts.ROBOT_LABEL]), "robot base or plate labelled as an object"


def _object_at(scene, point):
    below = np.asarray(point, float) - (0.0, 0.0, 0.003)
    hits = [i for i, obj in enumerate(scene.objects) if obj.contains(below[None])[0]]
    return hits[0] if hits else None


def _feasibility_errors(scene, grasp) -> list:
    """What is wrong with a grasp against the scene's true geometry (empty = feasible)."""
    p = np.asarray(grasp.position_base_m)
    target = _object_at(scene, p)
    if target is None:
        return ["its centre is on no object"]
    closing = np.asarray(grasp.closing_direction_base)
    across = np.cross([0.0, 0.0, 1.0], closing)
    tip = tcp_height_m(p[2]) - PANDA_FINGERTIP_BELOW_TCP_M
    errors = []
    # Between the fingers: the target, at every height the fingers reach, lies inside the opening.
    s = np.arange(-0.12, 0.12, 0.0005)
    for z in np.linspace(tip, p[2], 6):
        line = p + s[:, None] * closing
        line[:, 2] = z
        inside = scene.objects[target].contains(line)
        if inside.any() and np.abs(s[inside]).max() > grasp.width_m / 2 - 0.002:
            errors.append(f"{scene.objects[target].name} reaches {np.abs(s[inside]).max() * 1000:.0f} mm from the "
                          f"centre at z {z:.3f} but the opening is {grasp.width_m * 1000:.0f} mm")
            break
    # Under the pads, from the fingertip level up: nothing (objects, robot).
    along = grasp.width_m / 2 + np.linspace(0.0, PANDA_FINGER_THICKNESS_M, 5)
    side = np.linspace(-0.01, 0.01, 5)
    heights = np.linspace(tip + 0.002, tip + 0.15, 20)
    a, b, z = np.meshgrid(along, side, heights)
    for sign in (-1.0, 1.0):
        pts = p + sign * a.reshape(-1, 1) * closing + b.reshape(-1, 1) * across
        pts[:, 2] = z.reshape(-1)
        for part in (*scene.objects, *scene.robot_parts):
            if part.contains(pts).any():
                errors.append(f"a finger pad lands on {part.name}")
    return errors


def test_every_grasp_is_feasible_and_the_top_five_are_on_distinct_graspable_objects(cluttered):
    scene, frame, view = cluttered
    grasps = plan_tabletop_grasps(view, MODEL, None, top_k=5)
    assert len(grasps) >= 3
    names = []
    for grasp in grasps:
        errors = _feasibility_errors(scene, grasp)
        assert not errors, errors
        assert grasp.width_m <= GRIPPER_MAX_WIDTH_M
        names.append(scene.objects[_object_at(scene, grasp.position_base_m)].name)
    assert not set(names) & NOT_GRASPABLE, names           # no grasp on a face wider than the gripper
    distinct = len(set(names))
    assert names[:distinct] == list(dict.fromkeys(names)), names   # distinct objects come first
    assert distinct >= 3, names


def test_nothing_outside_the_workspace_box_is_an_object():
    scene = ts.cluttered_table()
    frame = ts.render(scene, seed=5)
    narrow = TabletopConfig(workspace=WorkspaceBox(x_m=(0.45, 0.85), y_m=(-0.4, 0.0)))
    view = perceive(frame.depth_m, frame.camera_k, frame.base_T_camera, narrow)
    names = {scene.objects[int(np.bincount(frame.labels[view.labels == label]).argmax()) - 1].name
             for label in view.object_ids}
    assert names <= {"rubber block", "sponge", "banana"}, names
    with pytest.raises(TabletopError, match="no table"):
        perceive(frame.depth_m, frame.camera_k, ts.look_at((0.86, 0.02, 0.90), (0.42, 0.0, 0.0)))  # wrong pose


SINGLES = (
    ts.Box((0.52, 0.03), (0.05, 0.04, 0.05), yaw_rad=0.3, name="block"),
    ts.Box((0.48, -0.05), (0.09, 0.035, 0.03), yaw_rad=-0.7, name="bar"),
    ts.Box((0.55, 0.06), (0.06, 0.06, 0.04), yaw_rad=0.0, name="foam cube"),
    ts.Cylinder((0.50, 0.00), 0.025, 0.07, name="wooden can"),
    ts.Cylinder((0.46, 0.08), 0.03, 0.12, name="soda can"),
    ts.LyingCylinder((0.52, -0.02), 0.02, 0.18, yaw_rad=0.9, name="marker"),
    ts.Sphere((0.50, 0.05, 0.035), 0.035, name="ball"),
    ts.Box((0.53, -0.08), (0.07, 0.045, 0.025), yaw_rad=1.2, name="sponge", material="dark"),
    ts.Cylinder((0.47, -0.03), 0.02, 0.10, name="bottle cap"),
    ts.Box((0.51, 0.02), (0.12, 0.03, 0.06), yaw_rad=0.5, name="long box"),
)


def test_overhead_single_objects_best_grasp_on_the_object_and_the_same_opening_at_every_resolution():
    for obj in SINGLES:
        widths = []
        for w, h in ts.MODES:
            scene = ts.overhead_single(obj, w, h)
            frame = ts.render(scene, seed=w)
            view = perceive(frame.depth_m, frame.camera_k, frame.base_T_camera)
            grasps = plan_tabletop_grasps(view, MODEL, None, top_k=1)
            assert grasps, f"{obj.name} at {w}x{h}: no grasp"
            errors = _feasibility_errors(scene, grasps[0])
            assert not errors, f"{obj.name} at {w}x{h}: {errors}"
            uv = image_projection(grasps[0], frame.base_T_camera, frame.camera_k)
            assert frame.labels[int(round(uv["v_px"])), int(round(uv["u_px"]))] == 1
            widths.append(grasps[0].width_m)
        spread = np.abs(np.asarray(widths) - np.mean(widths)).max()
        assert spread <= 0.003, f"{obj.name}: openings {np.round(widths, 4)} m (+-3 mm around their mean)"


def test_wrist_camera_with_the_fingers_in_view_best_grasp_on_the_object():
    """The hand's fingers hang into a wrist camera's view at the image's bottom edge (0.17-0.24 m from the lens,
    within the workspace's height range): every top-5 grasp must be on the object, none on a finger."""
    for index, obj in enumerate(SINGLES):
        for w, h in ts.MODES:
            distance = (0.17, 0.24)[index % 2]
            scene = ts.overhead_with_fingers(obj, w, h, height_m=0.38, finger_distance_m=distance)
            frame = ts.render(scene, seed=w + index)
            assert np.count_nonzero(frame.labels == ts.ROBOT_LABEL) > 0.01 * w * h      # the fingers are in view
            view = perceive(frame.depth_m, frame.camera_k, frame.base_T_camera)
            grasps = plan_tabletop_grasps(view, MODEL, None, top_k=5)
            assert grasps, f"{obj.name} at {w}x{h}: no grasp"
            for grasp in grasps:
                uv = image_projection(grasp, frame.base_T_camera, frame.camera_k)
                u, v = min(w - 1, int(round(uv["u_px"]))), min(h - 1, int(round(uv["v_px"])))
                assert frame.labels[v, u] == 1, f"{obj.name} at {w}x{h}: a grasp at ({u}, {v}) is not on it"


def test_the_height_map_has_the_networks_training_scale_at_every_resolution():
    assert CELL_M == pytest.approx(0.40 / 385.0)
    extents = []
    for w, h in ts.MODES:
        scene = ts.overhead_single(SINGLES[0], w, h)
        frame = ts.render(scene, seed=1)
        view = perceive(frame.depth_m, frame.camera_k, frame.base_T_camera)
        extents.append(view.areas_m2[view.object_ids[0]])
    assert max(extents) / min(extents) < 1.15     # the same footprint in square metres


def test_searches_sharing_a_frame_give_the_grasps_of_searches_on_their_own():
    """A frame's searches share each peak's feasibility (TabletopNetworkView.peak_grasps): in any order, every
    top_k gives the grasps a search on a freshly prepared frame gives."""
    from defgg_ros.planning.tabletop_grasps import prepare_tabletop, search_tabletop

    frame = ts.render(ts.cluttered_table(848, 480), seed=5)
    view = perceive(frame.depth_m, frame.camera_k, frame.base_T_camera)
    shared = prepare_tabletop(view, MODEL)
    for top_k in (5, 1, 3, 10, 2):
        alone = search_tabletop(prepare_tabletop(view, MODEL), top_k).grasps
        assert search_tabletop(shared, top_k).grasps == alone, f"top_k {top_k}"
        assert alone
    assert len(shared.peak_grasps) >= 10


def test_objects_cut_by_the_image_edge_are_known_and_ranked_after_those_seen_whole():
    """partly_seen_objects: an object half out of the frame (bottom edge) and one cut by the left invalid band
    are partly seen, one in the middle is not; the planner ranks grasps on objects seen whole first."""
    import dataclasses

    from defgg_ros.perception.tabletop import partly_seen_objects
    from defgg_ros.planning.tabletop_grasps import prepare_tabletop, search_tabletop

    base = ts.overhead_single(SINGLES[0], height_m=0.40)      # the whole view inside the workspace box
    k, pose = base.camera_k, base.base_T_camera

    def on_table_at(u, v):        # the table point seen at pixel (u, v)
        ray = pose[:3, :3] @ np.array([(u - k[0, 2]) / k[0, 0], (v - k[1, 2]) / k[1, 1], 1.0])
        point = pose[:3, 3] + ray * (-pose[2, 3] / ray[2])
        return float(point[0]), float(point[1])

    objects = (ts.Box(on_table_at(320, 240), (0.05, 0.04, 0.04), name="middle"),
               ts.Box(on_table_at(320, 440), (0.05, 0.04, 0.04), name="bottom edge"),   # ~1 cm out
               ts.Box(on_table_at(90, 240), (0.05, 0.04, 0.04), name="left band"))   # the band: ~53 px
    frame = ts.render(ts.TabletopScene(objects, pose), seed=4)
    view = perceive(frame.depth_m, frame.camera_k, frame.base_T_camera)
    label_of = {}
    for index, obj in enumerate(objects, start=1):
        found = view.labels[frame.labels == index]
        found = found[found > 0]
        assert found.size, f"{obj.name} not perceived"
        label_of[obj.name] = int(np.bincount(found).argmax())
    assert partly_seen_objects(view) == {label_of["bottom edge"], label_of["left band"]}
    # Ranking: mark the best object of the cluttered table as partly seen; it must come after the others.
    frame = ts.render(ts.cluttered_table(640, 480), seed=6)
    prepared = prepare_tabletop(perceive(frame.depth_m, frame.camera_k, frame.base_T_camera), MODEL)
    plain = search_tabletop(prepared, 5).grasps
    best = plain[0].object_id
    demoted = search_tabletop(dataclasses.replace(prepared, partly_seen=frozenset({best}), peak_grasps={}), 5).grasps
    objects_in_order = list(dict.fromkeys(g.object_id for g in demoted))
    assert objects_in_order[-1] == best and demoted[0].object_id != best, objects_in_order
    assert {g.object_id for g in demoted} == {g.object_id for g in plain}
