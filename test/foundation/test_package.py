"""Package metadata is valid for colcon/catkin_pkg and registers every tool."""
import configparser
import re
from pathlib import Path

from catkin_pkg.package import parse_package

ROOT = Path(__file__).resolve().parents[2]


def test_package_xml_is_valid():
    package = parse_package(ROOT / "package.xml")
    package.validate()
    deps = {d.name for d in package.exec_depends}
    for needed in ("rclpy", "sensor_msgs", "geometry_msgs", "trajectory_msgs", "visualization_msgs",
                   "defgg_interfaces", "python3-torch", "python3-numpy", "python3-opencv"):
        assert needed in deps
    assert package.get_build_type() == "ament_python"


def test_interface_package_xml_is_valid():
    package = parse_package(ROOT / "msg_defs" / "package.xml")
    package.validate()
    assert package.name == "defgg_interfaces"
    assert package.get_build_type() == "ament_cmake"


def test_every_console_script_target_exists():
    setup_text = (ROOT / "setup.py").read_text()
    targets = re.findall(r'"([\w\-]+)": "([\w.]+):(\w+)"', setup_text)
    assert len(targets) >= 11
    for name, module, func in targets:
        path = ROOT / (module.replace(".", "/") + ".py")
        assert path.exists(), f"console script {name}: {path} missing"
        assert re.search(rf"^def {func}\(", path.read_text(), re.M), f"{name}: no {func}() in {path}"


def test_ament_install_layout():
    cfg = configparser.ConfigParser()
    cfg.read(ROOT / "setup.cfg")
    assert cfg["install"]["install_scripts"] == "$base/lib/defgg_ros"
    assert (ROOT / "resource" / "defgg_ros").exists()
