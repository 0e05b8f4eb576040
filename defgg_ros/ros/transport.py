"""The cell's Fast DDS transports: large shared-memory segments and socket buffers for camera-sized messages.

With Fast DDS's defaults (512 kB shared-memory segments, ~208 kB UDP buffers) most fragments of a
1.8 MB depth frame were lost between processes (bench/bench_transport.py, docs/sessions.md); the
profile (fastdds_profile.xml next to this file: 32 MB segments, 4 MB UDP buffers) fixes that.
"""
import os
from pathlib import Path

FASTDDS_PROFILE = Path(__file__).resolve().with_name("fastdds_profile.xml")
FASTDDS_PROFILE_VARIABLE = "FASTRTPS_DEFAULT_PROFILES_FILE"


def use_large_message_transport() -> None:
    """Make this process (before rclpy.init) and the processes it starts use FASTDDS_PROFILE, unless set."""
    os.environ.setdefault(FASTDDS_PROFILE_VARIABLE, str(FASTDDS_PROFILE))
