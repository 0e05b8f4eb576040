"""defgg_ros.ros.memory: the malloc settings apply on glibc and change no result."""
import sys
import threading

import numpy as np
import pytest

from defgg_ros.ros import memory

pytestmark = pytest.mark.unit


@pytest.mark.skipif(not sys.platform.startswith("linux"), reason="glibc's mallopt")
def test_keep_freed_memory_applies_on_glibc_and_arrays_made_in_threads_stay_the_same():
    def work(out):
        rng = np.random.default_rng(3)
        out.append([float((rng.random((480, 640), np.float32) * k).sum()) for k in range(1, 6)])

    before, after = [], []
    thread = threading.Thread(target=work, args=(before,))
    thread.start()
    thread.join()
    assert memory.keep_freed_memory()
    thread = threading.Thread(target=work, args=(after,))
    thread.start()
    thread.join()
    assert before == after


def test_keep_freed_memory_is_false_without_mallopt(monkeypatch):
    def no_library(name):
        raise OSError(f"no {name}")

    monkeypatch.setattr(memory.ctypes, "CDLL", no_library)
    assert memory.keep_freed_memory() is False
