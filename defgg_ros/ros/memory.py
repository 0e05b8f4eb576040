"""glibc malloc settings for a process that allocates and frees camera-sized arrays at frame rate (no rclpy).

glibc serves an allocation above its mmap threshold (128 kB at start) with a fresh mmap and unmaps it on free,
and it returns a freed heap top above its trim threshold (128 kB) to the kernel; both thresholds rise on their
own only for the main thread's arena. A worker thread's numpy and OpenCV temporaries (a 640x480 float32 image
is 1.2 MB; one perception makes dozens) then come as new pages every frame, each faulted in and zeroed:
conversion and perception of a 640x480 frame took ~28 ms of CPU in a worker thread and ~19 ms in the main
thread, ~14 ms in either with these settings (issue 26, docs/perception.md "Latency"). Results are unchanged:
this only decides where memory comes from.
"""
import ctypes
import ctypes.util

M_TRIM_THRESHOLD = -1    # mallopt parameter numbers (malloc.h)
M_MMAP_THRESHOLD = -3
# glibc's largest mmap threshold on 64-bit (DEFAULT_MMAP_THRESHOLD_MAX): larger arrays are still mapped.
MMAP_THRESHOLD_BYTES = 32 << 20
# Freed memory stays with the process until this much is free at a heap's top.
TRIM_THRESHOLD_BYTES = 256 << 20


def keep_freed_memory(mmap_threshold_bytes: int = MMAP_THRESHOLD_BYTES,
                      trim_threshold_bytes: int = TRIM_THRESHOLD_BYTES) -> bool:
    """Fixed mmap and trim thresholds for every thread's arena (module docstring). False when the C library
    has no mallopt (not glibc: nothing changed)."""
    try:
        mallopt = ctypes.CDLL(ctypes.util.find_library("c") or "libc.so.6").mallopt
    except (OSError, AttributeError):
        return False
    mallopt.argtypes, mallopt.restype = (ctypes.c_int, ctypes.c_int), ctypes.c_int
    return bool(mallopt(M_MMAP_THRESHOLD, int(mmap_threshold_bytes))) and \
        bool(mallopt(M_TRIM_THRESHOLD, int(trim_threshold_bytes)))
