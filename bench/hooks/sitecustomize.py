"""Instruments the simulated cell inside `defgg-demo`'s driver process (bench/bench_motion_start.py --ros).

Python imports `sitecustomize` at start-up from the path; the bench puts this folder first on PYTHONPATH and
sets DEFGG_BENCH_CELL_LOG, so every process of the demo loads this file, and the one that imports
defgg_ros.sim.cell.sim_cell (the fake driver) gets SimCell wrapped: every 5th physics step writes the sim time, the
TCP position, the first object's position in the TCP frame and the gripper opening; every trajectory the
driver starts writes its first point and the arm's position then; every gripper grasp (G) and move (M) its
sim time. Nothing else changes.
"""
import importlib.abc
import importlib.util
import os
import sys

LOG = os.environ.get("DEFGG_BENCH_CELL_LOG")
EVERY_STEPS = 5


def _instrument(cell_module):
    import pybullet as p

    cls, out = cell_module.SimCell, open(f"{LOG}.{os.getpid()}", "w", buffering=1)   # lines survive a kill
    step, command, grasp, move = cls._step, cls.command_trajectory, cls.gripper_grasp, cls.gripper_move

    def logged_step(self):
        step(self)
        self._bench_steps = getattr(self, "_bench_steps", 0) + 1
        if self._bench_steps % EVERY_STEPS:
            return
        tcp_xyz, tcp_quat = self.tcp_pose()
        obj_xyz, obj_quat = self.object_poses()[0]
        inv = p.invertTransform(tcp_xyz, tcp_quat)
        rel = p.multiplyTransforms(inv[0], inv[1], obj_xyz, obj_quat)[0]
        out.write("S " + " ".join(f"{v:.8f}" for v in (self.time_s, *tcp_xyz, *rel, self.gripper_width_m())) + "\n")

    def logged_command(self, points, start_time_s=None):
        if points:
            first = points[0][1]
            out.write("T " + " ".join(f"{v:.6f}" for v in (self.time_s, *first, *self.arm_positions())) + "\n")
        return command(self, points, start_time_s)

    def logged(kind, call):
        def wrapper(self, *args):
            out.write(f"{kind} {self.time_s:.5f}\n")
            return call(self, *args)
        return wrapper

    cls._step, cls.command_trajectory = logged_step, logged_command
    cls.gripper_grasp, cls.gripper_move = logged("G", grasp), logged("M", move)


class _CellFinder(importlib.abc.MetaPathFinder):
    def find_spec(self, name, path, target=None):
        if name != "defgg_ros.sim.cell.sim_cell":
            return None
        sys.meta_path.remove(self)
        spec = importlib.util.find_spec(name)
        run_module = spec.loader.exec_module

        def exec_module(module):
            run_module(module)
            _instrument(module)

        spec.loader.exec_module = exec_module
        return spec


if LOG:
    sys.meta_path.insert(0, _CellFinder())
