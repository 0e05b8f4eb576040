"""Each script in examples/ runs as its README link says and prints what it promises (slow: a process each)."""
import re
import subprocess
import sys
from pathlib import Path

import pytest

from defgg_ros.perception import tabletop_scenes
from defgg_ros.rotations import matrix_to_quaternion_xyzw

EXAMPLES = Path(__file__).resolve().parents[1] / "examples"


def run_example(name: str, *args, timeout_s: float = 240.0) -> str:
    run = subprocess.run([sys.executable, str(EXAMPLES / name), *map(str, args)], capture_output=True, text=True,
                         timeout=timeout_s)
    assert run.returncode == 0, f"{name} exited {run.returncode}:\n{run.stdout}\n{run.stderr[-3000:]}"
    return run.stdout


@pytest.fixture(scope="module")
def sample_depth(tmp_path_factory) -> Path:
    """Example 01's generated frame: a 5 x 4 x 6 cm box 0.55 m under an overhead camera at (0.5, 0)."""
    path = tmp_path_factory.mktemp("examples") / "depth.png"
    assert "wrote" in run_example("01_plan_grasp_from_depth.py", path, "--make-sample")
    return path


@pytest.mark.unit
def test_there_are_three_numbered_examples_each_linked_from_the_readme():
    names = sorted(p.name for p in EXAMPLES.glob("[0-9][0-9]_*.py"))
    assert len(names) == 3
    readme = (EXAMPLES.parent / "README.md").read_text(encoding="utf-8")
    assert all(f"(examples/{name})" in readme for name in names), names


@pytest.mark.unit
def test_01_plans_a_grasp_on_the_box_from_a_depth_file(sample_depth):
    out = run_example("01_plan_grasp_from_depth.py", sample_depth)
    u_px, v_px, opening_mm = map(float, re.search(r"grasp 1: pixel \((\d+), (\d+)\), .*opening ([\d.]+) mm",
                                                  out).groups())
    assert abs(u_px - 319.5) < 40 and abs(v_px - 239.5) < 40, out     # the box sits under the image centre
    assert 0.0 < opening_mm <= 80.0, out


@pytest.mark.sim
def test_02_runs_one_trial_and_prints_its_label():
    out = run_example("02_one_fem_trial.py", "--modulus-pa", "2e9")    # rigid: a CPU-second, not a minute
    assert "protocol defgraspsim: status ok" in out, out
    assert re.search(r"^label: (positive|negative) \(mean [\d.]+ m/s\^2, threshold 25\)$", out, re.M), out


@pytest.mark.ros
def test_03_calls_plan_grasp_on_a_cell_from_its_own_node(inference_service, executor, spin, sample_depth):
    scene = tabletop_scenes.overhead_single(tabletop_scenes.Box((0.5, 0.0), (0.05, 0.04, 0.06)))
    base_T_camera = [*scene.base_T_camera[:3, 3], *matrix_to_quaternion_xyzw(scene.base_T_camera[:3, :3])]
    inference_service("examples_test_client", base_T_camera=[float(v) for v in base_T_camera],
                      plan_grasp_service="/examples_test/plan_grasp")
    script = [sys.executable, str(EXAMPLES / "03_call_plan_grasp.py"), "--depth", str(sample_depth),
              "--service", "/examples_test/plan_grasp", "--top-k", "1"]
    with subprocess.Popen(script, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True) as example:
        spin(executor, lambda: example.poll() is not None, 240.0, "example 03 to finish")   # the cell serves it
        out, err = example.communicate()
    assert example.returncode == 0, f"{out}\n{err[-3000:]}"
    x_m, y_m = map(float, re.search(r"grasp 1: \(([-\d.]+), ([-\d.]+), [-\d.]+\) m in ", out).groups())
    assert abs(x_m - 0.5) < 0.04 and abs(y_m) < 0.04, out              # on the box, in the base frame
