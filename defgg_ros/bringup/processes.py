"""Child processes of the bringup: started in their own session, logs forwarded with a prefix."""
import collections
import os
import signal
import subprocess
import sys
import threading

# How long a node gets to shut down after SIGINT, then after SIGTERM (s).
SIGINT_GRACE_S = 10.0
SIGTERM_GRACE_S = 5.0
# Log lines kept per process for error reports.
TAIL_LINES = 30


class ManagedProcess:
    """One node process; its stdout+stderr are printed as '[name] line'."""

    def __init__(self, name: str, argv: list, env: dict | None = None, out=None):
        self.name = name
        self.argv = argv
        self.tail = collections.deque(maxlen=TAIL_LINES)
        self._out = out or sys.stdout
        child_env = dict(os.environ if env is None else env)
        child_env.setdefault("PYTHONUNBUFFERED", "1")
        # ROS logs to a pipe are block-buffered by default: forward them as they happen.
        child_env.setdefault("RCUTILS_LOGGING_BUFFERED_STREAM", "0")
        child_env.setdefault("RCUTILS_COLORIZED_OUTPUT", "0")
        # Own session: a terminal Ctrl-C reaches only the bringup, which then
        # stops the nodes in order instead of all of them dying at once.
        self.popen = subprocess.Popen(argv, stdout=subprocess.PIPE, stderr=subprocess.STDOUT, env=child_env,
                                      start_new_session=True, text=True, bufsize=1)
        self._reader = threading.Thread(target=self._forward, name=f"log-{name}", daemon=True)
        self._reader.start()

    @property
    def pid(self) -> int:
        return self.popen.pid

    def _forward(self):
        for line in self.popen.stdout:
            line = line.rstrip("\n")
            self.tail.append(line)
            print(f"[{self.name}] {line}", file=self._out, flush=True)

    def returncode(self):
        return self.popen.poll()

    def stop(self) -> int:
        """SIGINT, then SIGTERM, then SIGKILL to this process's group; returns the exit code."""
        for sig, grace in ((signal.SIGINT, SIGINT_GRACE_S), (signal.SIGTERM, SIGTERM_GRACE_S), (signal.SIGKILL, 5.0)):
            if self.popen.poll() is not None:
                break
            try:
                os.killpg(self.popen.pid, sig)
            except ProcessLookupError:
                break
            try:
                self.popen.wait(timeout=grace)
            except subprocess.TimeoutExpired:
                continue
        code = self.popen.wait()
        self._reader.join(timeout=2.0)
        return code
