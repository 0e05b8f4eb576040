"""A session bag as a timeline of things to replay, each with what was recorded as its outcome.

Events, in the order they happened:
- `assignment`: the segmentation node's stiffness assignments changed;
- `frame`: a depth frame (+ camera_info, + colour) with the grasp the
  inference node published for it (matched by the depth stamp), or None;
- `plan`: a PlanGrasp call (request + response);
- `pick`: a PickAndPlace goal with its feedback and result.
No rclpy here: payloads are raw CDR (BagMessage) plus decoded views.
"""
from dataclasses import dataclass, field

from defgg_ros.sessions import session_topics as st
from defgg_ros.sessions.bag import BagMessage, SessionBagError, read_bag
from defgg_ros.sessions.selector import PAIR_WINDOW_S, nearest_stamp, restamp
from defgg_ros.sessions.session_topics import topics  # absolute names (bag channels)

# 2 (2026-11-29, one perceiver): PlanGrasp's request carries PerceivedObjects instead of a stiffness image, so a
# format-1 bag's recorded requests do not decode with today's definitions; sessions were re-recorded.
FORMAT = "defgg_session/2"


def stamp_ns(stamp) -> int:
    return int(stamp.sec) * 1_000_000_000 + int(stamp.nanosec)


@dataclass
class Frame:
    index: int
    stamp_ns: int
    depth: BagMessage
    camera_info: BagMessage
    color: BagMessage | None = None
    best_grasp: BagMessage | None = None     # the recorded expectation


@dataclass
class PlanCall:
    index: int
    request: BagMessage
    response: BagMessage | None


@dataclass
class Pick:
    index: int
    goal: BagMessage
    result: BagMessage | None
    feedback: list = field(default_factory=list)


@dataclass
class Event:
    kind: str            # assignment | frame | plan | pick
    log_time_ns: int
    payload: object


@dataclass
class Session:
    path: str
    metadata: dict
    events: list
    messages: list

    def of_kind(self, kind: str) -> list:
        return [e.payload for e in self.events if e.kind == kind]

    @property
    def frames(self) -> list:
        return self.of_kind("frame")

    @property
    def picks(self) -> list:
        return self.of_kind("pick")

    @property
    def static_transforms(self) -> list:
        """The recorded /tf_static messages (BagMessages, in order): the camera's calibration among them."""
        return [m for m in self.messages if m.topic == topics.TF_STATIC]


def _by_stamp(messages: list, topic: str) -> dict:
    return {stamp_ns(m.decode().header.stamp): m for m in messages if m.topic == topic}


def _pair_in_order(messages: list, first_topic: str, second_topic: str) -> list:
    """Requests/goals and their responses/results were written by one sequential client: pair by order."""
    firsts = [m for m in messages if m.topic == first_topic]
    seconds = [m for m in messages if m.topic == second_topic]
    return [(a, seconds[i] if i < len(seconds) else None) for i, a in enumerate(firsts)]


def _camera_info_for(path, infos: dict, depth: BagMessage, stamp: int) -> BagMessage:
    """The frame's camera_info; when it was lost (best effort), the nearest one restamped.

    The inference node matches depth and camera_info by exact stamp, and a
    camera's intrinsics do not change between frames.
    """
    if stamp in infos:
        return infos[stamp]
    if not infos:
        raise SessionBagError(f"{path}: depth frame at stamp {stamp} ns and no camera_info in the session")
    nearest = infos[min(infos, key=lambda s: abs(s - stamp))]
    return BagMessage(nearest.topic, nearest.msgtype, depth.log_time_ns, restamp(nearest.raw, stamp))


def _nearest(by_stamp: dict, stamp: int, window_s: float):
    """The message whose stamp is nearest `stamp` within window_s (a stream stamped by its own sensor), else None."""
    nearest = nearest_stamp(by_stamp, stamp, window_s)
    return None if nearest is None else by_stamp[nearest]


def _frames(path, messages: list) -> list:
    infos = _by_stamp(messages, topics.DEPTH_CAMERA_INFO)
    colors = _by_stamp(messages, topics.COLOR_IMAGE)
    grasps = _by_stamp(messages, topics.BEST_GRASP)
    events, seen = [], set()
    for m in messages:
        if m.topic != topics.DEPTH_IMAGE:
            continue
        stamp = stamp_ns(m.decode().header.stamp)
        if stamp in seen:  # a frame sent twice (a retried publish) is one frame
            continue
        seen.add(stamp)
        info = _camera_info_for(path, infos, m, stamp)
        frame = Frame(len(events), stamp, m, info, _nearest(colors, stamp, PAIR_WINDOW_S), grasps.get(stamp))
        events.append(Event("frame", m.log_time_ns, frame))
    return events


def build_session(path, metadata: dict, messages: list) -> Session:
    if metadata.get("format") != FORMAT:
        raise SessionBagError(f"{path}: session format {metadata.get('format')!r}, this replayer reads {FORMAT!r}")
    events = [Event("assignment", m.log_time_ns, m) for m in messages if m.topic == topics.STIFFNESS_ASSIGNMENTS]
    events += _frames(path, messages)
    for i, (request, response) in enumerate(_pair_in_order(messages, st.PLAN_REQUEST, st.PLAN_RESPONSE)):
        events.append(Event("plan", request.log_time_ns, PlanCall(i, request, response)))
    pick_pairs = _pair_in_order(messages, st.PICK_GOAL, st.PICK_RESULT)
    for i, (goal, result) in enumerate(pick_pairs):
        end = result.log_time_ns if result else float("inf")
        feedback = [m for m in messages if m.topic == st.PICK_FEEDBACK and goal.log_time_ns <= m.log_time_ns <= end]
        events.append(Event("pick", goal.log_time_ns, Pick(i, goal, result, feedback)))
    # The first assignment is the latched state the recorder got on joining: it was in force
    # before anything else in the session, even if it arrived after the first frame.
    if events and events[0].kind == "assignment":
        events[0].log_time_ns = min(m.log_time_ns for m in messages)
    # Stable sort: at equal times assignments come before frames before calls (the list order above).
    events.sort(key=lambda e: e.log_time_ns)
    return Session(str(path), metadata, events, messages)


def load_session(path) -> Session:
    """Read and check a session bag; SessionBagError says what is wrong with it."""
    metadata, messages = read_bag(path)
    session = build_session(path, metadata, messages)
    if not session.frames:
        raise SessionBagError(f"{path}: the session holds no depth frame on {topics.DEPTH_IMAGE}; nothing to replay")
    return session
