"""Session metadata: what a replay needs to rebuild the cell, and what it ran with.

Stored as JSON in the bag. The scene YAML text is embedded (not only its
path) so a replay rebuilds the recorded scene even after the file changed.
No rclpy here.
"""
import datetime
import subprocess
import sys
from dataclasses import asdict
from importlib import metadata as importlib_metadata
from pathlib import Path

from defgg_ros.provenance import file_sha256
from defgg_ros.ros.share import SOURCE_ROOT
from defgg_ros.sessions.compare import Tolerances
from defgg_ros.sessions.session import FORMAT


class MetadataError(ValueError):
    """Session metadata that is missing a field the replay needs."""


def software_version() -> dict:
    """Package version and, in a git checkout, the commit (+ '-dirty')."""
    try:
        version = importlib_metadata.version("defgg_ros")
    except importlib_metadata.PackageNotFoundError:
        version = "unknown"
    out = {"defgg_ros": version, "python": sys.version.split()[0]}
    try:
        commit = subprocess.run(["git", "-C", str(SOURCE_ROOT), "describe", "--always", "--dirty"],
                                capture_output=True, text=True, timeout=5, check=True).stdout.strip()
        out["git"] = commit
    except (OSError, subprocess.SubprocessError):
        pass
    return out


def scene_entry(scene_path) -> dict | None:
    if not scene_path:
        return None
    path = Path(scene_path)
    if not path.is_file():
        raise MetadataError(f"scene file {path} does not exist")
    return {"file": _repo_relative(path), "yaml": path.read_text(encoding="utf-8")}


def model_entry(model_path, use_stiffness: bool) -> dict:
    path = Path(model_path)
    if not path.is_file():
        raise MetadataError(f"model checkpoint {path} does not exist")
    return {"file": path.name, "path": _repo_relative(path), "sha256": file_sha256(path),
            "use_stiffness": bool(use_stiffness)}


def _repo_relative(path: Path) -> str:
    """Paths inside the repository are stored relative to it (sessions move between machines)."""
    try:
        return str(path.resolve().relative_to(SOURCE_ROOT))
    except ValueError:
        return str(path)


def make_metadata(name: str, *, source: str, scene_path, model_path, use_stiffness: bool,
                  parameters: dict, pick: bool, tolerances: Tolerances, note: str = "") -> dict:
    if source not in ("sim", "real"):
        raise MetadataError(f"source must be 'sim' or 'real', got {source!r}")
    return {
        "format": FORMAT,
        "name": name,
        "created_utc": datetime.datetime.now(datetime.UTC).isoformat(timespec="seconds"),
        "source": source,
        "note": note,
        "scene": scene_entry(scene_path),
        "model": model_entry(model_path, use_stiffness),
        "parameters": parameters,
        "software": software_version(),
        "replay": {"pick": bool(pick), "tolerances": asdict(tolerances)},
    }


def tolerances_of(metadata: dict) -> Tolerances:
    raw = (metadata.get("replay") or {}).get("tolerances") or {}
    try:
        return Tolerances(**{k: float(v) for k, v in raw.items()})
    except (TypeError, ValueError) as exc:
        raise MetadataError(f"bad replay tolerances in the session metadata: {exc}") from None


def pick_enabled(metadata: dict) -> bool:
    return bool((metadata.get("replay") or {}).get("pick", False))


def scene_yaml(metadata: dict) -> str:
    scene = metadata.get("scene")
    if not scene or not scene.get("yaml"):
        raise MetadataError("the session has no scene (recorded on a real cell?): picks cannot be replayed "
                            "in the simulator; replay with --no-pick")
    return scene["yaml"]


def updated_metadata(old: dict, model_path, use_stiffness: bool, tolerances: Tolerances) -> dict:
    """Metadata of a re-recorded session: same inputs, this model/software, new time."""
    new = dict(old)
    new["created_utc"] = datetime.datetime.now(datetime.UTC).isoformat(timespec="seconds")
    new["model"] = model_entry(model_path, use_stiffness)
    new["software"] = software_version()
    new["replay"] = {**(old.get("replay") or {}), "tolerances": asdict(tolerances)}
    new["updated_from"] = old.get("created_utc", "")
    return new
