"""The cell's nodes of a replay, each in its own process (defgg_ros/ros/launcher.py), and stopping them again.

Each node runs as `python -m defgg_ros.nodes.<node>` with its deployed overrides
(`sim_bringup/config/<node>.yaml`) plus a per-run override YAML, and logs to a file in the run
folder (shown when it dies). No readiness sleeping here: callers wait for the nodes'
services/actions and call `check_alive()` meanwhile.
"""
import sys
from dataclasses import dataclass, field
from pathlib import Path

import yaml

from defgg_ros.ros.launcher import NodeProcess, child_env, stop_all
from defgg_ros.ros.share import share_path

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
    """The deployed YAML of a node (source tree or installed share folder), None if there is none."""
    path = share_path("sim_bringup", "config", f"{name}.yaml")
    return path if path.is_file() else None


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


class NodeGraph:
    """The replay's node processes, in run_dir, on `domain_id` (None: the caller's domain)."""

    def __init__(self, run_dir, domain_id: int | None = None):
        self.domain_id = domain_id
        self.run_dir = Path(run_dir)
        self.run_dir.mkdir(parents=True, exist_ok=True)
        self.processes: dict[str, NodeProcess] = {}

    def start(self, spec: NodeSpec) -> None:
        if spec.name in self.processes:
            raise GraphError(f"node {spec.name} is already running")
        self.processes[spec.name] = NodeProcess(spec.name, node_command(spec, self.run_dir),
                                                env=child_env(self.domain_id),
                                                log_path=self.run_dir / f"{spec.name}.log")

    def log_tail(self, name: str) -> str:
        path = self.run_dir / f"{name}.log"
        lines = path.read_text(encoding="utf-8", errors="replace").splitlines() if path.exists() else []
        return "\n".join(f"    [{name}] {line}" for line in lines[-LOG_TAIL_LINES:])

    def check_alive(self) -> None:
        for name, process in self.processes.items():
            code = process.returncode()
            if code is not None:
                raise GraphError(f"node {name} exited with code {code} during the replay; its last log lines:\n"
                                 f"{self.log_tail(name)}")

    def stop(self, names) -> None:
        """Stop these nodes by the launcher's shutdown rule (SIGINT, then SIGTERM, then SIGKILL)."""
        stop_all([self.processes.pop(n) for n in names if n in self.processes])

    def stop_all(self) -> None:
        self.stop(list(reversed(self.processes)))

    def __enter__(self):
        return self

    def __exit__(self, *exc):
        self.stop_all()
