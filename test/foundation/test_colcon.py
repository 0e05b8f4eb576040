"""colcon (from PyPI, in the venv) on a workspace holding this repository, laid out as the README says.

colcon stops crawling at a package's folder, so msg_defs/ (defgg_interfaces) inside the repository
root (the ament_python package defgg_ros) is never found by itself; the README's workspace step
links it next to the repository (`ln -s defgg_ros/msg_defs defgg_interfaces`). vendor_interfaces/
(the venv-only franka_msgs, control_msgs, tf2_msgs) must never be built by colcon.
"""
import os
import shutil
import subprocess
import sys
from pathlib import Path

import pytest

REPO = Path(__file__).resolve().parents[2]
# What a colcon build of the package reads from the repository (the rest is data, results, docs).
PACKAGE_PARTS = ("package.xml", "setup.py", "setup.cfg", "resource", "defgg_ros", "sim_bringup", "models",
                 "msg_defs", "vendor_interfaces")


def _colcon(args, cwd, timeout_s=120):
    env = dict(os.environ, PATH=f"{Path(sys.executable).parent}{os.pathsep}{os.environ.get('PATH', '')}",
               AMENT_PREFIX_PATH=sys.prefix, CMAKE_PREFIX_PATH=sys.prefix, COLCON_HOME=str(cwd / ".colcon"))
    colcon = shutil.which("colcon", path=env["PATH"])
    assert colcon, "colcon is not installed in the venv (requirements.lock: colcon-core, colcon-ros)"
    return subprocess.run([colcon, *args], cwd=cwd, env=env, capture_output=True, text=True, timeout=timeout_s)


def _packages(listing: str) -> dict:
    rows = [line.split("\t") for line in listing.splitlines() if line.strip()]
    return {row[0]: row[2] for row in rows}


def _workspace(root: Path, link_interfaces: bool, copy: bool = False) -> Path:
    src = root / "src"
    src.mkdir(parents=True)
    if copy:
        (src / "defgg_ros").mkdir()
        for part in PACKAGE_PARTS:
            source = REPO / part
            if source.is_dir():
                shutil.copytree(source, src / "defgg_ros" / part, ignore=shutil.ignore_patterns("__pycache__"))
            else:
                shutil.copy2(source, src / "defgg_ros" / part)
    else:
        (src / "defgg_ros").symlink_to(REPO)
    if link_interfaces:
        (src / "defgg_interfaces").symlink_to(Path("defgg_ros") / "msg_defs")
    return root


@pytest.mark.unit
def test_colcon_list_finds_both_packages_with_the_readme_layout(tmp_path):
    result = _colcon(["list"], _workspace(tmp_path / "ws", link_interfaces=True))
    assert result.returncode == 0, result.stderr
    assert _packages(result.stdout) == {"defgg_interfaces": "(ros.ament_cmake)", "defgg_ros": "(ros.ament_python)"}
    graph = _colcon(["graph"], tmp_path / "ws")
    assert graph.returncode == 0 and "defgg_interfaces" in graph.stdout
    # Without the link, the repository alone is one package: why the README has that step.
    bare = _colcon(["list"], _workspace(tmp_path / "bare", link_interfaces=False))
    assert _packages(bare.stdout) == {"defgg_ros": "(ros.ament_python)"}


@pytest.mark.e2e
def test_colcon_build_installs_the_interfaces_and_a_working_package(tmp_path):
    ws = _workspace(tmp_path / "ws", link_interfaces=True, copy=True)
    result = _colcon(["build", "--event-handlers", "console_direct-", "--cmake-args",
                      f"-DPython3_EXECUTABLE={sys.executable}", "-DBUILD_TESTING=OFF"], ws, timeout_s=900)
    assert result.returncode == 0, result.stdout[-3000:] + result.stderr[-3000:]
    assert sorted(p.name for p in (ws / "install").iterdir() if p.is_dir()) == ["defgg_interfaces", "defgg_ros"]
    python = f"python{sys.version_info.major}.{sys.version_info.minor}"
    interfaces = ws / "install" / "defgg_interfaces" / "lib" / python / "site-packages"
    package = ws / "install" / "defgg_ros" / "lib" / python / "site-packages"
    for node in ("segmentation_node", "grasp_inference_node", "executor_node", "fake_panda_driver"):
        assert (ws / "install" / "defgg_ros" / "lib" / "defgg_ros" / node).is_file(), node
    share = ws / "install" / "defgg_ros" / "share" / "defgg_ros"
    assert (share / "sim_bringup" / "config" / "real_cell.yaml").is_file() and (share / "package.xml").is_file()
    # `ros2 launch defgg_ros real_cell.launch.py` finds each launch file once; franka.launch.py's controllers_yaml
    assert sorted(p.relative_to(share).as_posix() for p in share.rglob("*.launch.py")) == [
        "launch/real_cell.launch.py", "launch/sim_cell.launch.py"]
    assert (share / "sim_bringup" / "config" / "franka" / "controllers.yaml").is_file()
    # The installed package (not this source tree) loads its parameter schemas and the built interfaces.
    probe = ("import defgg_interfaces.srv, defgg_ros.ros.parameters as p, defgg_ros.ros.transport as t; "
             "p.load_schema('executor_node'); assert t.FASTDDS_PROFILE.is_file(); print(p.SCHEMA_DIR)")
    env = dict(os.environ, PYTHONPATH=os.pathsep.join([str(package), str(interfaces)]))
    out = subprocess.run([sys.executable, "-c", probe], cwd=tmp_path, env=env, capture_output=True, text=True,
                         timeout=120)
    assert out.returncode == 0, out.stderr
    assert Path(out.stdout.strip()).is_relative_to(package)
