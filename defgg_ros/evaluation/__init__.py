"""The paper's simulation experiments: model grasps -> FEM trials -> tables, figures, report.

Pieces (pure Python, no rclpy):

- ``tasks``: what "success" means for the shake and twist tasks.
- ``store``: the results file (JSON lines, one record per finished trial,
  resumable, torn-tail repair, no duplicates).
- ``sources``: which objects and moduli (named sets, a folder of meshes + YAML).
- ``scene`` / ``planning``: render an object at a modulus with the training
  camera, ask a GraspPredictor for its best grasps and turn them into
  world-frame grasps for ``defgg_ros.sim.trial.run_grasp_trial``.
- ``jobs`` / ``runner``: the trial list of an evaluation (main tables,
  sensitivity, multi-material), run in parallel worker processes; the
  parent alone appends to the results file.
- ``tables``, ``figures``, ``report``, ``cards``: outputs written from the
  results file (Markdown + CSV tables, plots, docs/results.md, model cards).

The ``defgg-eval`` command (``cli.py``) wires these together.
"""
