"""Where the package's data (sim_bringup/, models/) lives: the one resolver for every caller.

The source tree first (an editable pip install or a colcon --symlink-install runs from it), then the
installed share folder: the ament index's share/defgg_ros on a colcon install, else
<prefix>/share/defgg_ros of a plain pip install (setup.py data_files put the same files there).
"""
import sys
from pathlib import Path

PACKAGE = "defgg_ros"
SOURCE_ROOT = Path(__file__).resolve().parents[2]


def share_roots() -> list[Path]:
    """The folders searched, in order (no duplicates)."""
    roots = [SOURCE_ROOT]
    try:
        from ament_index_python.packages import get_package_share_directory

        roots.append(Path(get_package_share_directory(PACKAGE)))
    except Exception:  # no ament index (pip install) or the package is not registered in it
        pass
    roots.append(Path(sys.prefix) / "share" / PACKAGE)
    unique = []
    for root in roots:
        if root not in unique:
            unique.append(root)
    return unique


def interface_definition_dirs() -> list[Path]:
    """Where defgg_interfaces' .msg/.srv/.action texts live: its installed share folder, then the source tree's
    msg_defs/ (the sessions' bag reader parses them)."""
    return [Path(sys.prefix) / "share" / "defgg_interfaces", SOURCE_ROOT / "msg_defs"]


def demo_scene_file() -> Path:
    """The simulated cell's default scene (the fake driver's scene_file '' and `defgg-demo`'s --scene)."""
    return share_path("sim_bringup", "scenes", "demo.yaml")


def share_path(*parts: str) -> Path:
    """The first existing <root>/<parts>; else the source tree's path, so an error names where it belongs."""
    for root in share_roots():
        candidate = root.joinpath(*parts)
        if candidate.exists():
            return candidate
    return SOURCE_ROOT.joinpath(*parts)
