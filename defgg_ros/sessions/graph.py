"""Start the cell's nodes as child processes for a replay, and stop them again.

Each node runs as `python -m defgg_ros.nodes.<node>` with its deployed YAML
(`sim_bringup/config/<node>.yaml`) plus a per-run override YAML, logs to a
file in the run folder (shown when it dies), and in its own process group so
stopping it never touches anything else. No readiness sleeping here: callers
wait for the nodes' services/actions and call `check_alive()` meanwhile.
"""
import os
import signal
import subprocess
import sys
import time
from dataclasses import dataclass, field
from pathlib import Path

import yaml

CONFIG_DIR = Path(__file__).resolve().parents[2] / "sim_bringup" / "config"
# Large camera messages between processes need bigger shared-memory segments (see the file).
FASTDDS_PROFILE = Path(__file__).resolve().with_name("fastdds_profile.xml")
FASTDDS_PROFILE_VARIABLE = "FASTRTPS_DEFAULT_PROFILES_FILE"
STOP_TIMEOUT_S = 10.0
LOG_TAIL_LINES = 15


class GraphError(RuntimeError):
    """A node of the replay graph failed to start or died."""


@dataclass
class NodeSpec:
    name: str                                      # ROS node name = config file stem
    module: str                                    # python -m target
    parameters: dict = field(default_factory=dict)  # overrides of the YAML
    remaps: dict = field(default_factory=dict)      # topic remaps (from -> to)
    use_config: bool = True


def config_file(name: str) -> Path | None:
    """The deployed YAML of a node: the source tree's or the installed share/defgg_ros one."""
    for root in (CONFIG_DIR, Path(sys.prefix) / "share" / "defgg_ros" / "sim_bringup" / "config"):
        if (root / f"{name}.yaml").is_file():
            return root / f"{name}.yaml"
    return None


def node_command(spec: NodeSpec, run_dir: Path) -> list[str]:
    cmd = [sys.executable, "-m", spec.module, "--ros-args"]
    deployed = config_file(spec.name) if spec.use_config else None
    if deployed is not None:
        cmd += ["--params-file", str(deployed)]
    if spec.parameters:
        overrides = run_dir / f"{spec.name}.overrides.yaml"
        overrides.write_text(yaml.safe_dump({spec.name: {"ros__parameters": spec.parameters}}), encoding="utf-8")
        cmd += ["--params-file", str(overrides)]
    for source, target in spec.remaps.items():
        cmd += ["-r", f"{source}:={target}"]
    return cmd


def use_large_message_transport() -> None:
    """Make this process (before rclpy.init) and the nodes it starts use FASTDDS_PROFILE, unless set."""
    os.environ.setdefault(FASTDDS_PROFILE_VARIABLE, str(FASTDDS_PROFILE))


def _node_env(domain_id: int | None) -> dict:
    env = dict(os.environ)
    env.setdefault(FASTDDS_PROFILE_VARIABLE, str(FASTDDS_PROFILE))
    # Logs go to a file: unbuffered, so a node's last words are there when it dies.
    env.update(RCUTILS_LOGGING_BUFFERED_STREAM="0", PYTHONUNBUFFERED="1")
    if domain_id is not None:
        env.update(ROS_DOMAIN_ID=str(domain_id), ROS_AUTOMATIC_DISCOVERY_RANGE="LOCALHOST")
    return env


class NodeGraph:
    def __init__(self, run_dir, domain_id: int | None = None):
        self.domain_id = domain_id
        self.run_dir = Path(run_dir)
        self.run_dir.mkdir(parents=True, exist_ok=True)
        self.processes = {}

    def start(self, spec: NodeSpec) -> None:
        if spec.name in self.processes:
            raise GraphError(f"node {spec.name} is already running")
        log = open(self.run_dir / f"{spec.name}.log", "ab")
        try:
            self.processes[spec.name] = subprocess.Popen(
                node_command(spec, self.run_dir), stdout=log, stderr=subprocess.STDOUT, stdin=subprocess.DEVNULL,
                start_new_session=True, env=_node_env(self.domain_id))
        finally:
            log.close()

    def log_tail(self, name: str) -> str:
        path = self.run_dir / f"{name}.log"
        lines = path.read_text(encoding="utf-8", errors="replace").splitlines() if path.exists() else []
        return "\n".join(f"    [{name}] {line}" for line in lines[-LOG_TAIL_LINES:])

    def check_alive(self) -> None:
        for name, process in self.processes.items():
            code = process.poll()
            if code is not None:
                raise GraphError(f"node {name} exited with code {code} during the replay; its last log lines:\n"
                                 f"{self.log_tail(name)}")

    def stop(self, names) -> None:
        """SIGINT these nodes (rclpy shuts down cleanly), then SIGKILL what is left after a timeout."""
        stopping = [self.processes.pop(n) for n in names if n in self.processes]
        for process in stopping:
            if process.poll() is None:
                os.killpg(process.pid, signal.SIGINT)
        deadline = time.monotonic() + STOP_TIMEOUT_S
        for process in stopping:
            try:
                process.wait(timeout=max(0.1, deadline - time.monotonic()))
            except subprocess.TimeoutExpired:
                os.killpg(process.pid, signal.SIGKILL)
                process.wait()

    def stop_all(self) -> None:
        self.stop(list(self.processes))

    def __enter__(self):
        return self

    def __exit__(self, *exc):
        self.stop_all()
