"""The inference node's frames between preparation and answer (no rclpy): a frame converted for planning, a
frame through the network, and its searches by top_k, each made once by whoever asks first (the worker on
arrival, or a request), so a PlanGrasp of the latest frame is a lookup (docs/perception.md, "Fresh answers")."""
from __future__ import annotations

import dataclasses
import threading

import numpy as np


@dataclasses.dataclass(frozen=True)
class Frame:
    """One planning input: a depth frame and its perception, converted (the view rebuilt)."""

    header: object                  # std_msgs/Header of the depth image
    camera_k: np.ndarray            # 3x3
    objects: object                 # planning.tabletop_planner.PerceivedObjects: the rebuilt view and the moduli
    pose_frame_id: str              # the grasps' frame: the base frame, or defgg_table_estimate


class FrameSearches:
    """One frame's searches by top_k, each made once by whoever asks first (the worker's search on arrival, or a
    request); a later asker of the same top_k waits for it and gets the same grasps (or the same error)."""

    def __init__(self):
        self._lock = threading.Lock()
        self._entries = {}          # top_k -> [done Event, (result, grasps), error]

    def made(self, top_k: int) -> bool:
        """Whether the search for top_k is finished (made by the worker or an earlier request)."""
        with self._lock:
            entry = self._entries.get(top_k)
        return entry is not None and entry[0].is_set()

    def get(self, top_k: int, search):
        with self._lock:
            entry = self._entries.get(top_k)
            mine = entry is None
            if mine:
                entry = self._entries[top_k] = [threading.Event(), None, None]
        if mine:
            try:
                entry[1] = search()
            except Exception as exc:  # noqa: BLE001 - every asker gets the same error
                entry[2] = exc
            finally:
                entry[0].set()
        else:
            entry[0].wait()
        if entry[2] is not None:
            raise entry[2]
        return entry[1]


@dataclasses.dataclass(frozen=True)
class PreparedFrame:
    """A frame through the network (TabletopPlanner.network), ready for any number of searches."""

    frame: Frame
    prepared: object                # planning.tabletop_planner.PreparedFrame
    seconds: float                  # wall time of the preparation
    searches: FrameSearches = dataclasses.field(default_factory=FrameSearches, compare=False)
