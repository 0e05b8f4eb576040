"""Run `defgg-replay` as CI and users do: in a process of its own."""
import os
import subprocess
import sys

from defgg_ros.sessions import replay


def run_replay(*argv, timeout_s=900):
    """(exit code, stdout + stderr). Its own process, so its DDS participant is fresh (in a long-lived
    pytest process, after hundreds of earlier tests' contexts, replayed frames were sometimes lost)."""
    done = subprocess.run([sys.executable, "-m", replay.__name__, *map(str, argv)], capture_output=True,
                          text=True, timeout=timeout_s, env=dict(os.environ))
    return done.returncode, done.stdout + done.stderr
