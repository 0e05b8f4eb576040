"""The signal report as one figure (PNG): where the held accelerations sit against the threshold, how much of
their spread lies within a scene, and the stiffness-aware vs stiffness-blind oracle (data.signal)."""
from __future__ import annotations

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402

from defgg_ros.atomic import atomic_path  # noqa: E402
from defgg_ros.constants import SHAKE_ACCEL_LIMIT_MPS2, SHAKE_POSITIVE_THRESHOLD_MPS2  # noqa: E402
from defgg_ros.data.signal import (  # noqa: E402
    CARRY_GAP_POINTS,
    CARRY_WITHIN_SHARE,
    NEAR_THRESHOLD_BAND_MPS2,
    TOP_K,
    held_mps2,
    modulus_key,
)

BIN_MPS2 = 2.5


def signal_figure(report: dict, records: list[dict], path, title: str) -> None:
    """Write the three panels of `report` (signal_report of `records`) to `path` (PNG, atomically)."""
    fig, axes = plt.subplots(1, 3, figsize=(13.5, 3.6), gridspec_kw={"width_ratios": [2.2, 1, 1]})
    _held_panel(axes[0], report, records)
    _within_panel(axes[1], report)
    _oracle_panel(axes[2], report)
    fig.suptitle(title, fontsize=11)
    fig.tight_layout()
    with atomic_path(path) as tmp:
        fig.savefig(tmp, format="png", dpi=100)
    plt.close(fig)


def _held_panel(ax, report, records) -> None:
    bins = np.arange(0.0, SHAKE_ACCEL_LIMIT_MPS2 + BIN_MPS2, BIN_MPS2)
    threshold = SHAKE_POSITIVE_THRESHOLD_MPS2
    ax.axvspan(threshold - NEAR_THRESHOLD_BAND_MPS2, threshold + NEAR_THRESHOLD_BAND_MPS2, color="0.9",
               label=f"within {NEAR_THRESHOLD_BAND_MPS2:g} m/s² of the threshold")
    for e in report["moduli_pa"]:
        held = [v for r in records if float(r["youngs_modulus_pa"]) == e and (v := held_mps2(r)) is not None]
        rate = report["positive_rate"][modulus_key(e)]["rate"]
        ax.hist(held, bins=bins, histtype="step", linewidth=1.6, label=f"E = {e:.0e} Pa: {100 * rate:.0f} % positive")
    ax.axvline(threshold, color="k", linestyle="--", linewidth=1, label=f"label threshold {threshold:g} m/s²")
    ax.set_xlabel("mean held shake acceleration (m/s²; 0 = lift failed)")
    ax.set_ylabel("trials")
    ax.set_xlim(0, SHAKE_ACCEL_LIMIT_MPS2)
    ax.legend(fontsize=7, loc="upper left")
    ax.set_title("Held acceleration per modulus", fontsize=9)


def _within_panel(ax, report) -> None:
    keys = [modulus_key(e) for e in report["moduli_pa"]] + ["soft"]
    shares = [report["within_scene_share"].get(k) for k in keys]
    ax.bar(range(len(keys)), [100 * (s or 0.0) for s in shares], color=["tab:blue"] * (len(keys) - 1) + ["tab:gray"])
    ax.axhline(100 * CARRY_WITHIN_SHARE, color="tab:red", linestyle="--", linewidth=1,
               label=f"gate {100 * CARRY_WITHIN_SHARE:.0f} %")
    ax.set_xticks(range(len(keys)), keys, fontsize=8)
    ax.set_ylabel("% of the variance")
    ax.set_ylim(0, 100)
    ax.legend(fontsize=7)
    ax.set_title("Variance within object × modulus", fontsize=9)


def _oracle_panel(ax, report) -> None:
    oracle = report["oracle"]
    ax.set_title("Oracle: stiffness-aware vs blind", fontsize=9)
    if not oracle.get("objects"):
        ax.text(0.5, 0.5, "no candidate labelled\nat every modulus", ha="center", va="center", transform=ax.transAxes)
        return
    names = [("best", "best grasp"), (f"top{TOP_K}", f"best {TOP_K}")]
    x = np.arange(len(names))
    aware = [100 * oracle[k]["aware"] for k, _ in names]
    blind = [100 * oracle[k]["blind"] for k, _ in names]
    ax.bar(x - 0.18, aware, 0.36, label="stiffness-aware", color="tab:green")
    ax.bar(x + 0.18, blind, 0.36, label="stiffness-blind", color="tab:gray")
    for i, (k, _) in enumerate(names):
        gap = round(oracle[k]["gap_points"], 1) + 0.0     # no "-0.0"
        ax.annotate(f"gap {gap:+.1f}", (x[i], max(aware[i], blind[i]) + 2), ha="center", fontsize=8)
    ax.set_xticks(x, [label for _, label in names], fontsize=8)
    ax.set_ylabel(f"success (%); gate: gap ≥ {CARRY_GAP_POINTS:g} points")
    ax.set_ylim(0, 110)
    ax.legend(fontsize=7, loc="lower center")
