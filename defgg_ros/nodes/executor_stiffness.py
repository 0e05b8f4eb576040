"""The executor's side of a squeeze (issue 49 item 4): the measured modulus to the segmentation node.

SetStiffness replaces the segmentation node's whole set of entries, so the entries in force are read from its
latched assignments topic and the measured one is appended (later entries override earlier ones:
perception/stiffness_assignment.py). The object is addressed as the segmentation node addresses objects: by
image region, a whole-object entry takes every object whose mask centroid lies inside it. The region is a square
around the grasp's pixel, as wide as the grasp's opening in pixels (at least MIN_ROI_PX): the centroid of an
object grasped across lies within half the opening of the grasp centre, unless the grasp is far off its middle
(an end of a long bar), which then is not addressed (docs/squeeze.md says so). Replacing is idempotent, so the
call is re-sent until answered (ros/service.py).
"""
import threading

from defgg_interfaces.msg import ObjectStiffness, StiffnessAssignment
from defgg_interfaces.srv import SetStiffness

from defgg_ros.ros import qos
from defgg_ros.ros.service import ServiceTimeout, call_idempotent

MIN_ROI_PX = 16
MEASURED_PREFIX = "measured"


def measured_roi(grasp) -> tuple | None:
    """(x, y, w, h) around the grasp's image position, or None when the grasp has none (not planned here)."""
    u, v, width_px = float(grasp.center_u_px), float(grasp.center_v_px), float(grasp.width_px)
    if u <= 0.0 and v <= 0.0:
        return None
    side = int(round(max(width_px, MIN_ROI_PX)))
    return max(0, int(round(u - side / 2))), max(0, int(round(v - side / 2))), side, side


def _contains(entry: ObjectStiffness, u: float, v: float) -> bool:
    roi = entry.roi
    return roi.x_offset <= u < roi.x_offset + roi.width and roi.y_offset <= v < roi.y_offset + roi.height


class StiffnessUpdater:
    """Appends measured entries to the segmentation node's stiffness set (a node's subscription and client)."""

    def __init__(self, node, service: str, assignments_topic: str, callback_group):
        self._node = node
        self._client = node.create_client(SetStiffness, service, callback_group=callback_group)
        self._lock = threading.Lock()
        self._in_force: StiffnessAssignment | None = None
        self._heard = threading.Event()
        self._topic = assignments_topic
        node.create_subscription(StiffnessAssignment, assignments_topic, self._on_assignments, qos.LATCHED,
                                 callback_group=callback_group)

    def _on_assignments(self, msg: StiffnessAssignment) -> None:
        with self._lock:
            self._in_force = msg
        self._heard.set()

    def tell(self, grasp, modulus_pa: float, timeout_s: float) -> str:
        """Send the measured modulus for the object at the grasp; what happened, for a person (never raises)."""
        roi = measured_roi(grasp)
        if roi is None:
            return "not sent: the grasp has no image position (give a planned grasp to address its object)"
        if not self._client.wait_for_service(timeout_sec=timeout_s):
            return f"not sent: {self._client.srv_name} is not available"
        # The segmentation node latches its set from start-up: not heard within the timeout means another topic or
        # no node, and a set sent blind would replace every entry in force (configured and measured).
        if not self._heard.wait(timeout_s):
            return (f"not sent: nothing heard on {self._topic}, so the entries in force are unknown and sending would "
                    "replace them all (check stiffness_assignments_topic)")
        u, v = float(grasp.center_u_px), float(grasp.center_v_px)
        with self._lock:
            in_force = self._in_force
        kept = [e for e in (in_force.objects if in_force else [])
                if not (e.name.startswith(MEASURED_PREFIX) and _contains(e, u, v))]   # an older measurement there
        entry = ObjectStiffness(name=f"{MEASURED_PREFIX} at ({u:.0f}, {v:.0f}) px", youngs_modulus_pa=modulus_pa)
        entry.roi.x_offset, entry.roi.y_offset, entry.roi.width, entry.roi.height = roi
        request = SetStiffness.Request(objects=[*kept, entry])   # default 0: the default in force stays
        try:
            response = call_idempotent(self._client, request, timeout_s, "stiffness service")
        except (ServiceTimeout, RuntimeError) as error:
            return f"not sent: {error}"
        if not response.success:
            return f"refused by the segmentation node: {response.message}"
        return f"sent {modulus_pa:.3g} Pa for the object in image region {list(roi)}: {response.message}"
