"""defgg_interfaces/PerceivedObjects <-> planning.perceived_frame.PerceivedParts (the one perceiver's output)."""
import numpy as np
from defgg_interfaces.msg import ObjectStiffness, PerceivedObject, PerceivedObjects

from defgg_ros.perception.grasp_planning import PlanningError
from defgg_ros.perception.prepared_frames import Frame
from defgg_ros.planning.perceived_frame import ObjectSummary, PerceivedParts, moduli_image, view_from_parts
from defgg_ros.planning.tabletop_planner import PerceivedObjects as PlannerObjects
from defgg_ros.ros.conversions import (
    ConversionError,
    camera_info_to_k,
    check_image_size,
    check_same_size,
    depth_msg_to_metres,
    image_to_numpy,
    numpy_to_image,
    pose_from_transform,
    stamp_to_ns,
    transform_from_pose,
)

CAMERA_POSE_SOURCES = ("tf", "parameter", "table")


def perceived_to_msg(parts: PerceivedParts, header, base_frame: str, source: str) -> PerceivedObjects:
    """The message of one perceived frame (header: the depth image's)."""
    msg = PerceivedObjects(header=header, base_frame=base_frame, camera_pose_source=source,
                           camera_pose=pose_from_transform(parts.base_T_camera),
                           table_plane=[float(v) for v in parts.table_plane], cell_m=float(parts.cell_m),
                           grid_origin_xy_m=[float(v) for v in parts.grid_origin_xy_m],
                           workspace_box_m=[float(v) for v in parts.workspace_box_m],
                           min_object_height_m=float(parts.object_height_range_m[0]),
                           max_object_height_m=float(parts.object_height_range_m[1]),
                           depth_noise_baseline_m=float(parts.depth_noise[0]),
                           depth_noise_subpixel_rms_px=float(parts.depth_noise[1]))
    msg.labels = numpy_to_image(parts.labels, "mono8", header)
    msg.grid_height_m = numpy_to_image(np.asarray(parts.grid_height_m, np.float32), "32FC1", header)
    msg.grid_labels = numpy_to_image(parts.grid_labels, "mono8", header)
    msg.grid_pixel = numpy_to_image(np.asarray(parts.grid_pixel, np.int32), "32SC1", header)
    msg.grid_youngs_modulus_pa = numpy_to_image(np.asarray(parts.grid_youngs_modulus_pa, np.float32), "32FC1", header)
    for o in parts.objects:
        stiffness = ObjectStiffness(name=o.name, youngs_modulus_pa=o.youngs_modulus_pa)
        stiffness.roi.x_offset, stiffness.roi.y_offset, stiffness.roi.width, stiffness.roi.height = o.roi_px
        msg.objects.append(PerceivedObject(label=o.label, stiffness=stiffness, height_m=o.height_m,
                                           area_m2=o.area_m2, area_px=o.area_px, partly_seen=o.partly_seen))
    return msg


def is_empty(msg: PerceivedObjects) -> bool:
    """A PerceivedObjects field the client left at its default."""
    return msg.labels.width == 0 and msg.labels.height == 0 and not msg.objects and not msg.header.stamp.sec \
        and not msg.header.stamp.nanosec


def parts_from_msg(msg: PerceivedObjects) -> PerceivedParts:
    """PerceivedParts of a message; ConversionError naming what is malformed."""
    if msg.camera_pose_source not in CAMERA_POSE_SOURCES:
        raise ConversionError(f"perceived objects: camera_pose_source {msg.camera_pose_source!r} is not one of "
                              f"{CAMERA_POSE_SOURCES}")
    labels = _image(msg.labels, "labels", ("mono8", "8UC1"))
    grids = [_image(msg.grid_height_m, "grid_height_m", ("32FC1",)),
             _image(msg.grid_labels, "grid_labels", ("mono8", "8UC1")),
             _image(msg.grid_pixel, "grid_pixel", ("32SC1",)),
             _image(msg.grid_youngs_modulus_pa, "grid_youngs_modulus_pa", ("32FC1",))]
    plane = np.asarray(msg.table_plane, float)
    if not (np.all(np.isfinite(plane)) and abs(np.linalg.norm(plane[:3]) - 1.0) < 1e-6):
        raise ConversionError(f"perceived objects: table_plane {plane.tolist()} needs a unit normal")
    objects = tuple(ObjectSummary(int(o.label), o.stiffness.name, float(o.stiffness.youngs_modulus_pa),
                                  (o.stiffness.roi.x_offset, o.stiffness.roi.y_offset, o.stiffness.roi.width,
                                   o.stiffness.roi.height), float(o.height_m), float(o.area_m2), int(o.area_px),
                                  bool(o.partly_seen)) for o in msg.objects)
    try:
        pose = transform_from_pose(msg.camera_pose)
    except ValueError as exc:
        raise ConversionError(f"perceived objects: camera_pose: {exc}") from exc
    settings = [*msg.workspace_box_m, msg.min_object_height_m, msg.max_object_height_m, msg.depth_noise_baseline_m,
                msg.depth_noise_subpixel_rms_px]
    if not (np.all(np.isfinite(settings)) and msg.min_object_height_m < msg.max_object_height_m
            and msg.depth_noise_baseline_m > 0 and msg.depth_noise_subpixel_rms_px >= 0):
        raise ConversionError(f"perceived objects: workspace, height range or depth noise out of range: {settings}")
    return PerceivedParts(pose, tuple(plane.tolist()), labels, objects, tuple(msg.grid_origin_xy_m), *grids,
                          tuple(float(v) for v in msg.workspace_box_m),
                          (float(msg.min_object_height_m), float(msg.max_object_height_m)),
                          (float(msg.depth_noise_baseline_m), float(msg.depth_noise_subpixel_rms_px)),
                          cell_m=float(msg.cell_m))


def _image(msg, name: str, encodings) -> np.ndarray:
    if msg.encoding not in encodings:
        raise ConversionError(f"perceived objects: {name} must be {' or '.join(encodings)}, got {msg.encoding!r}")
    try:
        return image_to_numpy(msg)
    except ConversionError as exc:
        raise ConversionError(f"perceived objects: {name}: {exc}") from exc


def frame_from_messages(depth, perceived, info, max_image_size_px, grasp_rule: dict) -> Frame:
    """Depth + its PerceivedObjects + camera_info as the planner's Frame (the view rebuilt, no perception);
    grasp_rule: the executor's grasp_height_rule and grasp_depth_below_surface_m. Raises ValueError
    (ConversionError, PlanningError) with the reason."""
    if perceived.error:
        raise PlanningError(f"the segmentation node could not perceive this frame: {perceived.error}")
    check_image_size("depth", depth, max_image_size_px)
    check_same_size("depth", depth, "camera_info", info)
    check_same_size("depth", depth, "perceived labels", perceived.labels)
    if stamp_to_ns(perceived.header.stamp) != stamp_to_ns(depth.header.stamp):
        raise PlanningError("the perceived objects are of another frame (stamp) than the depth")
    camera_k = camera_info_to_k(info)
    depth_m = depth_msg_to_metres(depth)
    parts = parts_from_msg(perceived)
    if not parts.objects:
        raise PlanningError("no object found above the table in the workspace box (the segmentation node "
                            "perceived none)")
    view = view_from_parts(parts, depth_m, camera_k, **grasp_rule)
    return Frame(depth.header, camera_k, PlannerObjects(view, None, moduli_image(parts, depth_m.shape), None),
                 perceived.base_frame)
