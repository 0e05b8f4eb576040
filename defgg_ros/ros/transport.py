"""The cell's Fast DDS transports: large shared-memory segments and socket buffers for camera-sized messages.

With Fast DDS's defaults (512 kB shared-memory segments, ~208 kB UDP buffers) most fragments of a
1.8 MB depth frame were lost between processes (bench/bench_transport.py, docs/sessions.md); the
profile (fastdds_profile.xml next to this file: 32 MB segments, 4 MB UDP buffers) fixes that.
The profile also frees each service request's memory after the request (its "service" reader profile), which
rmw_fastrtps reads only with RMW_FASTRTPS_USE_QOS_FROM_XML=1. That variable is set only by the call that also
chooses the profile (FASTRTPS_DEFAULT_PROFILES_FILE unset before it): with any other profile file, or none,
it would put every reader and writer on Fast DDS's own defaults (fixed-size preallocated histories, synchronous
publication), so a process that set or removes the profile variable itself (a test's monkeypatch) never gets
it. Whoever points FASTRTPS_DEFAULT_PROFILES_FILE at this profile by hand sets RMW_FASTRTPS_USE_QOS_FROM_XML=1
too (the nodes' processes inherit both from the bringup).
"""
import os
from pathlib import Path

FASTDDS_PROFILE = Path(__file__).resolve().with_name("fastdds_profile.xml")
FASTDDS_PROFILE_VARIABLE = "FASTRTPS_DEFAULT_PROFILES_FILE"
QOS_FROM_XML_VARIABLE = "RMW_FASTRTPS_USE_QOS_FROM_XML"


def use_large_message_transport() -> None:
    """Make this process (before rclpy.init) and the processes it starts use FASTDDS_PROFILE, unless set."""
    if FASTDDS_PROFILE_VARIABLE not in os.environ:
        os.environ[FASTDDS_PROFILE_VARIABLE] = str(FASTDDS_PROFILE)
        os.environ.setdefault(QOS_FROM_XML_VARIABLE, "1")
