"""Exact-stamp synchroniser for a few streams (no rclpy, no message_filters).

The segmentation node stamps its PerceivedObjects with the depth frame's
stamp, so depth, perceived objects and camera_info of one frame share an exact
stamp. Each stream keeps a small cache keyed by stamp (integer ns); when a
stamp is present in every stream, that set is emitted and everything older
is dropped (a newer complete set makes older partial ones useless).
"""
from collections import OrderedDict

# Frames arrive at <= 30 Hz and the segmentation node's PerceivedObjects lags its depth by one perception
# (tens of ms; under load a few hundred): 20 depth frames (0.67 s at 30 Hz, ~37 MB at 1280x720) keep the
# depth of every frame it perceives. A perception slower than that misses the freshness target anyway.
DEFAULT_CACHE_SIZE = 20
# A stamp this far behind the last emitted set is a clock that started again (a bag played with --loop, a
# restarted simulator's /clock, a camera driver's restart), not a late frame: start matching afresh.
CLOCK_RESTART_NS = 2_000_000_000


class StampSynchronizer:
    """add(stream, stamp_ns, item) -> {stream: item} when the stamp is complete, else None."""

    def __init__(self, streams, cache_size: int = DEFAULT_CACHE_SIZE):
        self._streams = tuple(streams)
        if len(set(self._streams)) != len(self._streams) or not self._streams:
            raise ValueError(f"streams must be distinct names, got {streams!r}")
        if cache_size < 1:
            raise ValueError(f"cache_size must be >= 1, got {cache_size}")
        self._cache_size = int(cache_size)
        self._caches = {name: OrderedDict() for name in self._streams}
        self._last_emitted_ns = None
        self.dropped = 0  # items evicted from a full cache or older than the last emitted set

    @property
    def streams(self) -> tuple:
        return self._streams

    def add(self, stream: str, stamp_ns: int, item):
        if stream not in self._caches:
            raise KeyError(f"unknown stream {stream!r}; known: {self._streams}")
        stamp_ns = int(stamp_ns)
        if self._last_emitted_ns is not None and stamp_ns <= self._last_emitted_ns:
            if self._last_emitted_ns - stamp_ns < CLOCK_RESTART_NS:
                self.dropped += 1  # late arrival of a frame already emitted or superseded
                return None
            self.restart()
        cache = self._caches[stream]
        cache[stamp_ns] = item
        cache.move_to_end(stamp_ns)
        while len(cache) > self._cache_size:
            cache.popitem(last=False)
            self.dropped += 1
        if all(stamp_ns in c for c in self._caches.values()):
            return self._emit(stamp_ns)
        return None

    def _emit(self, stamp_ns: int) -> dict:
        matched = {name: self._caches[name][stamp_ns] for name in self._streams}
        for cache in self._caches.values():
            for old in [s for s in cache if s <= stamp_ns]:
                del cache[old]
                if old != stamp_ns:
                    self.dropped += 1
        self._last_emitted_ns = stamp_ns
        return matched

    def restart(self) -> None:
        """Forget every cached item and the last emitted stamp (the clock started again)."""
        self.dropped += sum(len(c) for c in self._caches.values())
        for cache in self._caches.values():
            cache.clear()
        self._last_emitted_ns = None

    def pending(self, stream: str) -> int:
        return len(self._caches[stream])
