"""Play a session into the live graph and collect what the graph answers.

SessionPlayer publishes the recorded camera frames (raw CDR, original
stamps) and waits for the inference node's grasp on each stamp; `replay`
walks the session's events in order — stiffness assignments through
SetStiffness, frames, PlanGrasp calls, PickAndPlace goals — and returns one
report Row per frame/call/pick.
"""
import threading
import time
from dataclasses import dataclass

from defgg_interfaces.action import PickAndPlace
from defgg_interfaces.msg import Grasp, StiffnessAssignment
from defgg_interfaces.srv import PlanGrasp
from rclpy.duration import Duration
from rclpy.node import Node
from rclpy.qos import DurabilityPolicy, HistoryPolicy, QoSProfile, ReliabilityPolicy
from sensor_msgs.msg import CameraInfo, Image, JointState
from tf2_msgs.msg import TFMessage

from defgg_ros.ros import qos
from defgg_ros.ros.cell_client import CellCallError
from defgg_ros.ros.conversions import ns_to_stamp
from defgg_ros.ros.tf import tf_qos
from defgg_ros.sessions.compare import GraspSummary, PickOutcome, Tolerances, grasp_problems, pick_problems
from defgg_ros.sessions.live_message import live_message
from defgg_ros.sessions.report import Row, diff_text
from defgg_ros.sessions.selector import restamp
from defgg_ros.sessions.session import Frame, Session, stamp_ns
from defgg_ros.sessions.session_topics import topics  # absolute names (bag channels)

# Re-send a frame this often while waiting: camera topics are best effort, a frame can be lost.
RESEND_PERIOD_S = 1.5
# Reliable publisher (matches the nodes' best-effort camera subscriptions and delivers when it can).
FRAME_QOS = QoSProfile(history=HistoryPolicy.KEEP_LAST, depth=5, reliability=ReliabilityPolicy.RELIABLE,
                       durability=DurabilityPolicy.VOLATILE)


@dataclass
class ReplayOptions:
    tolerances: Tolerances
    pick: bool = True
    grasp_timeout_s: float = 30.0      # a frame whose grasp is expected
    no_grasp_wait_s: float = 5.0       # a frame recorded without a grasp: how long to make sure
    plan_timeout_s: float = 30.0
    pick_timeout_s: float = 300.0


class SessionPlayer(Node):
    def __init__(self, node_name="defgg_session_player", **kwargs):
        super().__init__(node_name, **kwargs)
        # Frames go out with fresh, strictly increasing "replay stamps" (the inference node only matches
        # stamps newer than the last it matched), mapped back to the recorded stamp on the way in.
        self._next_stamp_ns = time.time_ns()
        self._recorded_of = {}
        self._depth_pub = self.create_publisher(Image, topics.DEPTH_IMAGE, FRAME_QOS)
        self._info_pub = self.create_publisher(CameraInfo, topics.DEPTH_CAMERA_INFO, FRAME_QOS)
        self._color_pub = self.create_publisher(Image, topics.COLOR_IMAGE, FRAME_QOS)
        self._static_pub = self.create_publisher(TFMessage, topics.TF_STATIC, tf_qos(static=True))
        self._grasps = {}
        self._changed = threading.Condition()
        self.create_subscription(Grasp, topics.BEST_GRASP, self._on_grasp, qos.STATE)
        self.joint_states_seen = threading.Event()
        self.create_subscription(JointState, topics.JOINT_STATES, lambda _: self.joint_states_seen.set(),
                                 qos.SENSOR_DATA)

    def _on_grasp(self, msg: Grasp):
        with self._changed:
            self._grasps[stamp_ns(msg.header.stamp)] = msg
            self._changed.notify_all()

    def publish_static_transforms(self, messages, ack_timeout_s: float = 5.0) -> int:
        """Latch the session's recorded /tf_static transforms as one message (a latched publisher keeps only its
        last; the newest transform per parent -> child wins); returns how many. The perception nodes' camera
        pose comes from them, as it did in the recorded cell."""
        latest = {}
        for message in messages:
            for transform in live_message(message, TFMessage).transforms:
                latest[(transform.header.frame_id, transform.child_frame_id)] = transform
        if latest:
            self._static_pub.publish(TFMessage(transforms=list(latest.values())))
            self._static_pub.wait_for_all_acked(Duration(seconds=ack_timeout_s))
        return len(latest)

    def _send(self, frame: Frame) -> int:
        """Publish the frame under a new replay stamp; returns it."""
        self._next_stamp_ns = max(self._next_stamp_ns + 1_000_000, time.time_ns())
        stamp = self._next_stamp_ns
        with self._changed:
            self._recorded_of[stamp] = frame.stamp_ns
        self._info_pub.publish(restamp(frame.camera_info.raw, stamp))
        if frame.color is not None:
            self._color_pub.publish(restamp(frame.color.raw, stamp))
        self._depth_pub.publish(restamp(frame.depth.raw, stamp))
        return stamp

    def restore(self, grasp):
        """Put the recorded stamp back into a grasp computed on a replayed frame (in place; returns it)."""
        recorded = self._recorded_of.get(stamp_ns(grasp.header.stamp))
        if recorded is not None:
            for header in (grasp.header, grasp.pose_base.header, grasp.pose_camera.header):
                header.stamp = ns_to_stamp(recorded)
        return grasp

    def feed_frame(self, frame: Frame, wait_s: float, alive=lambda: None):
        """Publish a recorded frame until the graph's grasp for it arrives (stamp restored); None after wait_s.

        Each re-send carries a new stamp: a lost piece of an earlier send cannot block a later one.
        """
        deadline = time.monotonic() + wait_s
        sent = set()
        while True:
            sent.add(self._send(frame))
            resend_at = min(deadline, time.monotonic() + RESEND_PERIOD_S)
            with self._changed:
                if self._changed.wait_for(lambda: sent & self._grasps.keys(), resend_at - time.monotonic()):
                    grasp = self._grasps[min(sent & self._grasps.keys())]
                    for stamp in sent:
                        self._grasps.pop(stamp, None)
                    return self.restore(grasp)
            alive()
            if time.monotonic() >= deadline:
                return None


def _summary(grasp) -> GraspSummary | None:
    return GraspSummary.of(grasp) if grasp is not None else None


def _brief(summary) -> str:
    return summary.brief() if summary is not None else "none"


class Replay:
    """One pass over a session's events against a live graph."""

    def __init__(self, session: Session, player: SessionPlayer, client, options: ReplayOptions,
                 alive=lambda: None, log=print, recorder=None):
        self.session, self.player, self.client, self.options = session, player, client, options
        self.alive, self.log, self.recorder = alive, log, recorder
        self.rows = []
        self.uncompared_frames = 0
        self.grasps_by_stamp = {}      # replayed grasp per frame stamp (frames and plan calls)
        self.last_fed_stamp = None
        self.frames_by_stamp = {f.stamp_ns: f for f in session.frames}

    def run(self) -> list[Row]:
        for event in self.session.events:
            getattr(self, f"_{event.kind}")(event.payload)
            self.alive()
        return self.rows

    def _assignment(self, message):
        assignment = live_message(message, StiffnessAssignment)
        self.client.set_stiffness(assignment.objects, assignment.default_youngs_modulus_pa)
        if self.recorder is not None:
            self.recorder.write_raw(message.topic, message.raw)

    def _feed(self, frame: Frame):
        wait_s = self.options.grasp_timeout_s if frame.best_grasp is not None else self.options.no_grasp_wait_s
        self.log(f"  feeding frame {frame.index} (stamp {frame.stamp_ns / 1e9:.3f} s)")
        if self.recorder is not None:  # --update: the frame goes into the new bag as sent
            camera = [(m.topic, m.raw) for m in (frame.camera_info, frame.color, frame.depth) if m is not None]
            self.recorder.write_frame(frame.stamp_ns, camera)
        actual = self.player.feed_frame(frame, wait_s, self.alive)
        self.last_fed_stamp = frame.stamp_ns
        if actual is not None:
            self.grasps_by_stamp[frame.stamp_ns] = actual
            if self.recorder is not None:
                self.recorder.write_grasp(actual)
        return actual

    def _ensure_fed(self, stamp):
        """Make the frame with this recorded stamp the latest one the inference node has seen."""
        if stamp in self.frames_by_stamp and stamp != self.last_fed_stamp:
            self._feed(self.frames_by_stamp[stamp])

    def _frame(self, frame: Frame):
        if frame.best_grasp is None:
            # A live cell drops frames it is too busy for: no grasp recorded says nothing about the
            # network's answer, so such a frame is not compared (and only fed when a call used it).
            self.uncompared_frames += 1
            return
        expected = _summary(frame.best_grasp.decode())
        actual = _summary(self._feed(frame))
        item = f"frame {frame.index} @{frame.stamp_ns / 1e9:.3f}s"
        self.rows.append(Row(item, _brief(expected), _brief(actual), diff_text(expected, actual),
                             grasp_problems(expected, actual, self.options.tolerances)))

    def _plan(self, call):
        request = live_message(call.request, PlanGrasp.Request)
        recorded = call.response.decode() if call.response is not None else None
        if recorded is not None and recorded.grasps and request.depth.width == 0:
            self._ensure_fed(stamp_ns(recorded.grasps[0].header.stamp))  # the call planned on the latest frame
        sent_ns = time.time_ns()
        response = self.client.plan(request, self.options.plan_timeout_s)
        for grasp in response.grasps:
            self.player.restore(grasp)
        if self.recorder is not None:
            self.recorder.record_plan(request, response, sent_ns)
        expected = _summary(recorded.grasps[0]) if recorded is not None and recorded.grasps else None
        actual = _summary(response.grasps[0]) if response.grasps else None
        problems = grasp_problems(expected, actual, self.options.tolerances)
        if recorded is not None and bool(recorded.success) != bool(response.success):
            problems.insert(0, f"success {response.success} (recorded {recorded.success}): {response.message}")
        if response.grasps:
            self.grasps_by_stamp[stamp_ns(response.grasps[0].header.stamp)] = response.grasps[0]
        self.rows.append(Row(f"plan {call.index}", _brief(expected), _brief(actual), diff_text(expected, actual),
                             problems))

    def _pick(self, pick):
        recorded = PickOutcome.of(pick.result.decode()) if pick.result is not None else None
        if not self.options.pick:
            self.rows.append(Row(f"pick {pick.index}", recorded.brief() if recorded else "none", "skipped"))
            return
        goal = live_message(pick.goal, PickAndPlace.Goal)
        self._prepare_goal(goal, pick)
        self._wait_for_joint_states()
        self.log(f"  pick {pick.index}: executing in the simulated cell ...")
        if self.recorder is not None:
            self.recorder.record_pick_goal(goal, time.time_ns())
        on_feedback = self.recorder.record_pick_feedback if self.recorder is not None else None
        result = self.client.pick(goal, on_feedback, timeout_s=self.options.pick_timeout_s)
        self.player.restore(result.grasp_used)
        if self.recorder is not None:
            self.recorder.record_pick_result(result)
        actual = PickOutcome.of(result)
        self.rows.append(Row(f"pick {pick.index}", recorded.brief() if recorded else "none", actual.brief(), "",
                             pick_problems(recorded, actual)))

    def _wait_for_joint_states(self):
        """The executor aborts ("driver silent") when a goal comes before the driver's first joint states."""
        deadline = time.monotonic() + self.options.grasp_timeout_s
        while not self.player.joint_states_seen.wait(0.5):
            self.alive()
            if time.monotonic() > deadline:
                raise CellCallError(f"no {topics.JOINT_STATES} from the simulated driver within "
                                    f"{self.options.grasp_timeout_s:g} s")

    def _prepare_goal(self, goal, pick):
        """Make the goal use this replay's grasp, not the recorded one."""
        if goal.plan_grasp:
            # The executor plans on the latest frame: make it the frame the recorded pick planned on.
            if pick.result is not None:
                self._ensure_fed(stamp_ns(pick.result.decode().grasp_used.header.stamp))
            return
        stamp = stamp_ns(goal.grasp.header.stamp)
        if stamp in self.grasps_by_stamp:
            goal.grasp = self.grasps_by_stamp[stamp]
