"""A planned grasp as defgg_interfaces/Grasp (poses in the camera and the base frame, image projection, the
object's estimated mass and finger force, the pads' contact radii and line lengths) and as rviz finger markers:
the inference node's outputs."""
import numpy as np
from defgg_interfaces.msg import Grasp
from geometry_msgs.msg import PoseStamped
from std_msgs.msg import Header
from visualization_msgs.msg import Marker, MarkerArray

from defgg_ros.grip_force import GripRuleError, LabelGripRule
from defgg_ros.model.inference import CheckpointError
from defgg_ros.perception.grasp_planning import finger_boxes_in_grasp
from defgg_ros.planning.grip_estimate import grip_estimate
from defgg_ros.planning.section_outline import SECTION_CELL_M
from defgg_ros.planning.tabletop_grasps import base_T_grasp, image_projection
from defgg_ros.ros.conversions import pose_from_transform, transform_from_pose


def label_grip_rule(predictor, model_path) -> LabelGripRule:
    """The grip force rule of the model's labels (its weights record it; legacy when they do not)."""
    try:
        return LabelGripRule.from_meta(predictor.checkpoint_meta.get("meta"))
    except GripRuleError as exc:
        raise CheckpointError(f"{model_path}: {exc}") from exc


def grasp_msg(grasp, frame, network, grip_rule: LabelGripRule, density_kg_m3: float, warn) -> Grasp:
    """A TabletopGrasp of a prepared frame (perception/prepared_frames.Frame) as a Grasp message. pose_base is
    in the perception's pose frame: the base frame, or the table frame (the executor refuses it)."""
    base_T_camera = frame.objects.view.base_T_camera
    b_T_g = base_T_grasp(grasp)
    image = image_projection(grasp, base_T_camera, frame.camera_k)
    msg = Grasp(header=frame.header)
    msg.pose_camera = PoseStamped(header=frame.header, pose=pose_from_transform(np.linalg.inv(base_T_camera) @ b_T_g))
    msg.pose_base = PoseStamped(header=Header(stamp=frame.header.stamp, frame_id=frame.pose_frame_id),
                                pose=pose_from_transform(b_T_g))
    msg.width_m = float(grasp.width_m)
    msg.quality = float(grasp.quality)
    msg.angle_rad = image["angle_rad"]
    msg.center_u_px, msg.center_v_px = image["u_px"], image["v_px"]
    msg.width_px = image["width_px"]
    msg.youngs_modulus_pa = float(grasp.youngs_modulus_pa)
    msg.object_id = int(grasp.object_id)
    _pad_contacts(msg, grasp, warn)
    _section(msg, grasp, warn)
    _grip_fields(msg, grasp, network, grip_rule, density_kg_m3, warn)
    return msg


# The pads' contacts a Grasp carries (planning/contact_radii.py via TabletopGrasp) and what the executor's squeeze
# does without each (docs/squeeze.md).
PAD_CONTACT_FIELDS = {"contact_radii_m": "the flat law", "contact_line_lengths_m": "point contacts only"}


def _pad_contacts(msg: Grasp, grasp, warn) -> None:
    """Grasp.contact_radii_m and contact_line_lengths_m. A Grasp type without one is an interface build older than
    this source: said once per field, and the grasps go without it."""
    for name, without in PAD_CONTACT_FIELDS.items():
        if _installed_has(msg, name, without, warn):
            setattr(msg, name, [float(v) for v in getattr(grasp, name)])


_STALE_FIELDS_SAID = set()


def _installed_has(msg: Grasp, name: str, without: str, warn) -> bool:
    """Whether the installed Grasp type has the field; if not (a build older than this source), said once."""
    if hasattr(msg, name):
        return True
    if name not in _STALE_FIELDS_SAID:
        _STALE_FIELDS_SAID.add(name)
        warn(f"the installed defgg_interfaces/Grasp has no {name}: its build is older than this source (rebuild "
             f"it: scripts/bootstrap.sh); grasps go without it, the squeeze uses {without}")
    return False


def _section(msg: Grasp, grasp, warn) -> None:
    """Grasp.section_cell_m, section_rows and section_heights_m (planning/section_outline.py via TabletopGrasp);
    an older interface build: said once, the squeeze uses the contact laws."""
    heights = getattr(grasp, "section_heights_m", None)
    if not _installed_has(msg, "section_heights_m", "the contact laws", warn) or heights is None:
        return
    msg.section_cell_m = float(SECTION_CELL_M)
    msg.section_rows = int(heights.shape[0])
    msg.section_heights_m = np.asarray(heights, np.float32).ravel().tolist()


def _grip_fields(msg: Grasp, grasp, network, grip_rule: LabelGripRule, density_kg_m3: float, warn) -> None:
    """Grasp.estimated_mass_kg and finger_force_n (planning/grip_estimate.py)."""
    try:
        grip = grip_estimate(network, grasp.object_id, grip_rule, float(density_kg_m3))
    except ValueError as exc:     # a grasp is always on an object's cells; never lose the grasp over this
        warn(f"no grip estimate for object {grasp.object_id} ({exc}); Grasp.finger_force_n 0: the executor's "
             "legacy force")
        return
    msg.estimated_mass_kg = grip.mass_kg
    msg.finger_force_n = grip.finger_force_n
    if grip_rule.needs_mass and grip.finger_force_n <= 0.0:
        warn(f"object {grasp.object_id}: no volume seen, so no mass for the labels' grip force; the executor will "
             "close with its legacy force")


def finger_markers(grasp: Grasp) -> MarkerArray:
    """The two finger boxes at the grasp, coloured by its quality (red 0 .. green 1)."""
    base_T_grasp_m = transform_from_pose(grasp.pose_base.pose)
    markers = MarkerArray()
    for index, (grasp_T_finger, size) in enumerate(finger_boxes_in_grasp(grasp.width_m)):
        marker = Marker(header=grasp.pose_base.header, ns="defgg_grasp", id=index, type=Marker.CUBE,
                        action=Marker.ADD, pose=pose_from_transform(base_T_grasp_m @ grasp_T_finger))
        marker.scale.x, marker.scale.y, marker.scale.z = size
        marker.color.r, marker.color.g, marker.color.a = float(1.0 - grasp.quality), float(grasp.quality), 0.8
        markers.markers.append(marker)
    return markers
