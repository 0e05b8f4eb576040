"""defgg_ros: an ament_python package (colcon) that also installs with pip."""
import glob
import os

from setuptools import find_packages, setup

PACKAGE = "defgg_ros"


def share(*patterns, exclude=()):
    """Group files by folder for data_files under share/defgg_ros (folders in `exclude` left out)."""
    groups = {}
    for pattern in patterns:
        for path in glob.glob(pattern, recursive=True):
            if os.path.isfile(path) and not path.startswith(tuple(exclude)) and "__pycache__" not in path:
                groups.setdefault(os.path.dirname(path), []).append(path)
    return [(os.path.join("share", PACKAGE, folder), files) for folder, files in sorted(groups.items())]


# `ros2 launch defgg_ros <file>` searches the whole share folder and refuses a name found twice, so the launch
# files are installed once, to share/defgg_ros/launch, and left out of the sim_bringup copy.
LAUNCH_FILES = sorted(glob.glob("sim_bringup/launch/*.launch.py"))


NODES = {
    "segmentation_node": "defgg_ros.nodes.segmentation_node:main",
    "grasp_inference_node": "defgg_ros.nodes.grasp_inference_node:main",
    "executor_node": "defgg_ros.nodes.executor_node:main",
    "fake_panda_driver": "defgg_ros.nodes.fake_panda_driver_node:main",
}
TOOLS = {
    "defgg-bringup": "defgg_ros.bringup.cli:main",
    "defgg-demo": "defgg_ros.demo:main",
    "defgg-train": "defgg_ros.train.cli:main",
    "defgg-datagen": "defgg_ros.data.datagen_cli:main",
    "defgg-eval": "defgg_ros.evaluation.cli:main",
    "defgg-record": "defgg_ros.sessions.record:main",
    "defgg-replay": "defgg_ros.sessions.replay:main",
}

setup(
    name=PACKAGE,
    version="0.1.0",
    packages=find_packages(exclude=["test", "test.*"]),
    package_data={"defgg_ros.sim": ["tet_meshes/*.npz"], "defgg_ros.ros": ["params/*.yaml", "fastdds_profile.xml"]},
    data_files=[
        ("share/ament_index/resource_index/packages", [f"resource/{PACKAGE}"]),
        (f"share/{PACKAGE}", ["package.xml"]),
    ]
    + [(f"share/{PACKAGE}/launch", LAUNCH_FILES)]
    + share("sim_bringup/**/*", "models/*", exclude=("sim_bringup/launch/",)),
    install_requires=["setuptools"],
    zip_safe=False,
    maintainer="defgg_ros maintainers",
    maintainer_email="maintainers@defgg-ros.org",
    description="Stiffness-aware grasp synthesis (Def-GG-CNN) for a Franka Panda cell.",
    license="Apache-2.0",
    entry_points={
        "console_scripts": [f"{name} = {target}" for name, target in {**NODES, **TOOLS}.items()],
    },
)
