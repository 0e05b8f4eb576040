"""What an evaluation run would still cost: simulations per task and modulus, CPU-hours where the folder's own
finished simulations give a cost (`defgg-eval run --plan-only` prints it)."""
from __future__ import annotations

from collections import defaultdict


def pending_budget(ready: list, to_run: dict, finished: list) -> dict:
    """What a run would do: trials settled without a simulation (reused or no grasp), and the simulations
    still to run per task and modulus, with CPU-hours where the folder's own finished simulations of that task
    and modulus give a mean cost (none for a fresh folder: bench/bench_eval.py gives costs)."""
    cost = defaultdict(list)
    for rec in finished:
        if rec.get("reused_from") is None and rec.get("cpu_s") is not None:
            cost[(rec["task"], float(rec["youngs_modulus_pa"]))].append(rec["cpu_s"])
    per_cell = defaultdict(int)
    for recs in to_run.values():
        rec = recs[0][0]
        per_cell[(rec["task"], float(rec["youngs_modulus_pa"]))] += 1
    cells = []
    for (task, e), n in sorted(per_cell.items()):
        mean = sum(cost[(task, e)]) / len(cost[(task, e)]) if cost[(task, e)] else None
        cells.append({"task": task, "youngs_modulus_pa": e, "simulations": n, "finished_simulations":
                      len(cost[(task, e)]), "cpu_h": None if mean is None else n * mean / 3600.0})
    known = [c["cpu_h"] for c in cells if c["cpu_h"] is not None]
    trials = len(ready) + sum(len(recs) for recs in to_run.values())
    return {"trials": trials, "settled_without_simulation": len(ready), "simulations": sum(per_cell.values()),
            "cells": cells,
            "cpu_h_estimated": sum(known) if known else None,
            "cells_without_cost": sum(c["cpu_h"] is None for c in cells)}


def budget_lines(budget: dict) -> list[str]:
    """pending_budget as lines for the terminal."""
    lines = [f"{budget['trials']} trials pending: {budget['simulations']} simulations to run (trials with the same "
             f"grasp share one); {budget['settled_without_simulation']} settled without one (a finished identical "
             "simulation reused, or no grasp proposed)"]
    for c in budget["cells"]:
        cost = (f"~{c['cpu_h']:.1f} CPU-h (mean of {c['finished_simulations']} finished here)"
                if c["cpu_h"] is not None else "no finished simulation here to estimate from")
        lines.append(f"  {c['task']:5s} E = {c['youngs_modulus_pa']:.0e} Pa: {c['simulations']:5d}  {cost}")
    if budget["cpu_h_estimated"] is not None:
        missing = budget["cells_without_cost"]
        lines.append(f"estimated: ~{budget['cpu_h_estimated']:.1f} CPU-h"
                     + (f" plus {missing} cell(s) without a cost" if missing else ""))
    return lines
