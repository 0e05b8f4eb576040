"""Rewrite build-machine paths baked into the rosidl wheels' CMake exports.

The ros-jazzy-* wheels were built in a manylinux image whose Python lives in
/opt/python/cp311-cp311; their exported CMake files name its include folder
and numpy's include folder, which do not exist here, and cmake then fails at
the generate step. Pointing them at this interpreter's folders fixes that.
"""
import glob
import os
import sys
import sysconfig

import numpy

BUILD_PYTHON = "/opt/python/cp311-cp311"
REWRITES = {
    f"{BUILD_PYTHON}/lib/python3.11/site-packages/numpy/_core/include": numpy.get_include(),
    f"{BUILD_PYTHON}/include/python3.11": sysconfig.get_paths()["include"],
}


def main(venv: str) -> int:
    pattern = os.path.join(venv, "share", "*", "cmake", "*.cmake")
    changed = 0
    for path in glob.glob(pattern):
        with open(path, encoding="utf-8") as f:
            text = f.read()
        new = text
        for old, repl in REWRITES.items():
            new = new.replace(old, repl)
        if new != text:
            tmp = path + ".tmp"
            with open(tmp, "w", encoding="utf-8") as f:
                f.write(new)
            os.replace(tmp, path)
            changed += 1
    if changed:
        print(f"[bootstrap] rewrote build paths in {changed} CMake file(s)")
    return 0


if __name__ == "__main__":
    sys.exit(main(sys.argv[1]))
