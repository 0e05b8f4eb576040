"""Node processes: the one way the bringup, the session replays, the tests and the benches start and stop
a node in a child process.

Each process runs in its own session (process group): a terminal's Ctrl-C reaches only the parent,
which then stops its children in order, and stopping one never touches anything else. Its output is
either forwarded line by line as "[name] line" (the bringup, the demo) or appended to a log file (a
replay's run folder); either way the last lines are kept for error reports.

One shutdown rule (`NodeProcess.stop`): SIGINT to the group (rclpy shuts down cleanly), then SIGTERM
after SIGINT_GRACE_S, then SIGKILL after SIGTERM_GRACE_S.

A parent killed before it could stop its children (SIGKILL, a crash, a test runner's SIGTERM) must not
leave them running: each child learns its parent's pid (SUPERVISOR_PID_VARIABLE) and, through
`watch_supervisor` in the node's main, stops itself with SIGTERM once that parent is gone (SIGTERM, not
SIGINT: a shell starts background jobs with SIGINT ignored, and every entry point stops cleanly on SIGTERM).
"""
import collections
import os
import signal
import subprocess
import sys
import threading
import time
from pathlib import Path

from defgg_ros.ros.transport import FASTDDS_PROFILE, FASTDDS_PROFILE_VARIABLE

SUPERVISOR_PID_VARIABLE = "DEFGG_SUPERVISOR_PID"
SUPERVISOR_POLL_S = 0.5
# Longer than the executor's exit_stop_timeout_s (2 s): it stops the arm before it exits, and the driver it
# stops through must still run (stop_all stops one process after the other).
SIGINT_GRACE_S = 10.0
SIGTERM_GRACE_S = 5.0
SIGKILL_WAIT_S = 5.0
TAIL_LINES = 30


def child_env(domain_id: int | None = None, base: dict | None = None) -> dict:
    """The environment of a node process: unbuffered output (a node's last words reach the log when it
    dies), the cell's Fast DDS profile unless one is set, and optionally a private localhost-only domain."""
    env = dict(os.environ if base is None else base)
    env.setdefault("PYTHONUNBUFFERED", "1")
    env.setdefault("RCUTILS_LOGGING_BUFFERED_STREAM", "0")  # ROS logs to a pipe are block-buffered otherwise
    env.setdefault("RCUTILS_COLORIZED_OUTPUT", "0")
    env.setdefault(FASTDDS_PROFILE_VARIABLE, str(FASTDDS_PROFILE))
    if domain_id is not None:
        env.update(ROS_DOMAIN_ID=str(domain_id), ROS_AUTOMATIC_DISCOVERY_RANGE="LOCALHOST")
    return env


class NodeProcess:
    """One child process. out: a text stream for "[name] line" forwarding (default stdout); log_path: append
    the output to this file instead."""

    def __init__(self, name: str, argv: list, env: dict | None = None, out=None, log_path=None, cwd=None):
        self.name = name
        self.argv = list(argv)
        self.log_path = Path(log_path) if log_path is not None else None
        self._tail = collections.deque(maxlen=TAIL_LINES)
        self._out = out or sys.stdout
        self._reader = None
        env = child_env(base=env)
        env[SUPERVISOR_PID_VARIABLE] = str(os.getpid())
        if self.log_path is not None:
            with open(self.log_path, "ab") as log:
                self.popen = subprocess.Popen(self.argv, stdout=log, stderr=subprocess.STDOUT,
                                              stdin=subprocess.DEVNULL, env=env, cwd=cwd, start_new_session=True)
        else:
            self.popen = subprocess.Popen(self.argv, stdout=subprocess.PIPE, stderr=subprocess.STDOUT,
                                          stdin=subprocess.DEVNULL, env=env, cwd=cwd, start_new_session=True,
                                          text=True, bufsize=1)
            self._reader = threading.Thread(target=self._forward, name=f"log-{name}", daemon=True)
            self._reader.start()

    @property
    def pid(self) -> int:
        return self.popen.pid

    @property
    def tail(self) -> list:
        """The last TAIL_LINES lines of output."""
        if self.log_path is not None:
            text = self.log_path.read_text(encoding="utf-8", errors="replace") if self.log_path.exists() else ""
            return text.splitlines()[-TAIL_LINES:]
        return list(self._tail)

    def _forward(self):
        for line in self.popen.stdout:
            line = line.rstrip("\n")
            self._tail.append(line)
            print(f"[{self.name}] {line}", file=self._out, flush=True)

    def returncode(self):
        """None while running, else the exit code (negative: killed by that signal)."""
        return self.popen.poll()

    def stop(self) -> int:
        """SIGINT, then SIGTERM, then SIGKILL to this process's group; returns the exit code."""
        for sig, grace_s in ((signal.SIGINT, SIGINT_GRACE_S), (signal.SIGTERM, SIGTERM_GRACE_S),
                             (signal.SIGKILL, SIGKILL_WAIT_S)):
            if self.popen.poll() is not None:
                break
            try:
                os.killpg(self.popen.pid, sig)
            except ProcessLookupError:
                break
            try:
                self.popen.wait(timeout=grace_s)
            except subprocess.TimeoutExpired:
                continue
        code = self.popen.wait()
        if self._reader is not None:
            self._reader.join(timeout=2.0)
        return code


def stop_all(processes) -> dict:
    """Stop these NodeProcesses one after the other, in the order given (callers pass reverse start order);
    returns name -> exit code."""
    return {process.name: process.stop() for process in processes}


def _alive(pid: int) -> bool:
    """Running, not a zombie (a killed parent nobody has reaped yet is dead for us)."""
    try:
        with open(f"/proc/{pid}/stat", encoding="ascii", errors="replace") as stat:
            return stat.read().rsplit(")", 1)[1].split()[0] != "Z"
    except (FileNotFoundError, ProcessLookupError, IndexError):
        return False


def watch_supervisor(name: str, poll_s: float = SUPERVISOR_POLL_S) -> threading.Thread | None:
    """In a child started by NodeProcess: SIGTERM this process once the parent that started it is gone.

    Returns the watching thread, or None when this process was not started by a NodeProcess (no
    SUPERVISOR_PID_VARIABLE, or one naming a live process that is not our parent: a grandchild that
    inherited the variable). Polls the parent pid: the kernel's parent-death signal would follow the
    parent *thread*, and a NodeProcess may be made in a worker thread that ends before its child.
    """
    # Taken out of the environment: processes this one starts with plain subprocess must not inherit it.
    value = os.environ.pop(SUPERVISOR_PID_VARIABLE, "")
    if not value.isdigit():
        return None
    supervisor = int(value)
    if os.getppid() != supervisor and _alive(supervisor):
        return None

    def watch():
        while os.getppid() == supervisor:
            time.sleep(poll_s)
        try:
            print(f"{name}: the process that started it (pid {supervisor}) is gone: shutting down",
                  file=sys.stderr, flush=True)
        except OSError:   # its output went to the dead parent's pipe
            pass
        os.kill(os.getpid(), signal.SIGTERM)

    thread = threading.Thread(target=watch, name="supervisor-watch", daemon=True)
    thread.start()
    return thread
