"""setup.py's arguments, as colcon and pip pass them to setuptools, without building anything."""
import functools
import os
import runpy
from pathlib import Path

import setuptools

REPO = Path(__file__).resolve().parents[2]


@functools.cache
def setup_arguments() -> dict:
    captured, original, cwd = {}, setuptools.setup, Path.cwd()
    setuptools.setup = lambda **kwargs: captured.update(kwargs)
    try:
        os.chdir(REPO)   # setup.py globs relative to the package folder, as colcon and pip run it
        runpy.run_path(str(REPO / "setup.py"), run_name="__main__")
    finally:
        setuptools.setup = original
        os.chdir(cwd)
    return captured


def console_scripts() -> dict:
    """console script -> the module whose main() it runs."""
    rows = [line.split("=", 1) for line in setup_arguments()["entry_points"]["console_scripts"]]
    return {name.strip(): target.strip().split(":")[0] for name, target in rows}


def installed_files() -> dict:
    """destination under the install prefix (share/defgg_ros/...) -> source path in the repository."""
    out = {}
    for folder, files in setup_arguments()["data_files"]:
        for source in files:
            destination = str(Path(folder) / Path(source).name)
            assert destination not in out, f"{destination} installed twice"
            out[destination] = source
    return out
