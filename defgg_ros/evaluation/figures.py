"""Figures of the evaluation (matplotlib, Agg backend, PNG written atomically)."""
from __future__ import annotations

import math

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402

from defgg_ros.atomic import atomic_path  # noqa: E402

# The paper's sensitivity curve (Fig. "Grasp success versus error in stiffness"), drawn for reference.
PAPER_SENSITIVITY = ((-60, 21), (-45, 36.42), (-30, 58), (-15, 69), (-5, 75), (0, 75.9), (5, 72.85), (15, 68.3),
                     (30, 56.4), (45, 38.57), (60, 25.2))


def _save(fig, path) -> None:
    with atomic_path(path) as tmp:
        fig.savefig(tmp, format="png", dpi=110, bbox_inches="tight")
    plt.close(fig)


# key -> (style, colour, offset of the n= labels in points; None: no labels, they would overlap)
_SCOPE_STYLES = {"all": ("s-", "tab:blue", 6), "ranks": ("^--", "tab:green", None), "best": ("o:", "tab:orange", -11)}


def common_n_label(counts) -> str:
    """', n = N per point' when every point of a curve has the same n, else '' (each point is labelled)."""
    distinct = set(counts)
    return f", n = {distinct.pop()} per point" if len(distinct) == 1 else ""


def sensitivity_plot(scopes: dict, path, label: str) -> None:
    """Success over all stiffnesses vs stiffness input error, one curve per grasp scope; n in the legend
    when a curve has one n, else at each point."""
    fig, ax = plt.subplots(figsize=(5.5, 3.8))
    for key, (scope_label, cells) in scopes.items():
        style, color, dy = _SCOPE_STYLES[key]
        xs = [e for e, c in cells.items() if c.rate_pct is not None]
        ys = [cells[e].rate_pct for e in xs]
        same_n = common_n_label([cells[x].graded for x in xs])
        ax.plot(xs, ys, style, color=color, label=f"{label}, {scope_label} (this simulator{same_n})")
        # One n for the whole curve goes in the legend; per-point labels only when they differ.
        for x, y in zip(xs, ys) if dy is not None and not same_n else ():
            ax.annotate(f"n={cells[x].graded}", (x, y), textcoords="offset points", xytext=(0, dy),
                        ha="center", fontsize=7, color=color)
    px, py = zip(*PAPER_SENSITIVITY)
    ax.plot(px, py, "--", color="grey", alpha=0.7, label="paper (Isaac Gym)")
    ax.set_xlabel("error of stiffness input [%]")
    ax.set_ylabel("shake success over all stiffnesses [%]")
    ax.set_xlim(-65, 65)
    ax.set_ylim(0, 100)
    ax.grid(True, linestyle="--", alpha=0.5)
    ax.legend(loc="upper center", bbox_to_anchor=(0.5, -0.16), fontsize=8)  # below: clear of the points
    _save(fig, path)


def grasp_segment(center_uv, angle_rad: float, width_px: float) -> np.ndarray:
    """2x2 end points (u, v) of the closing line of a grasp in the image."""
    d = np.array([math.cos(angle_rad), math.sin(angle_rad)]) * width_px / 2
    c = np.asarray(center_uv, dtype=float)
    return np.stack([c - d, c + d])


def strategy_figure(panels: list, path, title: str) -> None:
    """One row per panel: stiffness input, quality map with the best grasps, depth with the best grasp.

    panels: dicts with "label", "stiffness" (encoded, HxW), "depth_m", "q" (HxW, crop coordinates),
    "grasps" (list of (u, v, angle, width_px) in crop coordinates, best first).
    """
    fig, axes = plt.subplots(len(panels), 3, figsize=(10, 3.3 * len(panels)), squeeze=False)
    for row, panel in zip(axes, panels):
        row[0].imshow(panel["stiffness"], cmap="viridis", vmin=0, vmax=1)
        row[0].set_title(f"{panel['label']}: stiffness input", fontsize=9)
        row[1].imshow(panel["q"], cmap="magma", vmin=0, vmax=1)
        row[1].set_title("quality map Q, top grasps", fontsize=9)
        row[2].imshow(panel["depth_m"], cmap="gray_r")
        row[2].set_title("depth, best grasp", fontsize=9)
        for i, (u, v, a, w) in enumerate(panel["grasps"]):
            seg = grasp_segment((u, v), a, w)
            color = "cyan" if i == 0 else "white"
            row[1].plot(seg[:, 0], seg[:, 1], "-", color=color, lw=2 if i == 0 else 1)
            if i == 0:
                row[2].plot(seg[:, 0], seg[:, 1], "-o", color="red", lw=2, ms=3)
        for ax in row:
            ax.set_xticks([])
            ax.set_yticks([])
    fig.suptitle(title, fontsize=10)
    _save(fig, path)


# The paper's simulated margins (with stiffness minus without, points): common 75.9 - 40.3, adversarial 68 - 57.6.
PAPER_MARGIN_PTS = {"common": 35.6, "adversarial": 10.4}


def seeds_figure(studies: list, path) -> None:
    """The seed studies at a glance: a panel per object set; per study each seed's paired margin (dots) and the
    mean over seeds with its 95 % bootstrap interval over objects (diamond and bar). studies: [(label,
    [SeedSummary per object set])]."""
    sets = list(dict.fromkeys(s.object_set for _, summaries in studies for s in summaries))
    fig, axes = plt.subplots(1, len(sets), figsize=(3.2 * len(sets) + 1.0, 3.6), squeeze=False)
    for ax, object_set in zip(axes[0], sets):
        for x, (_, summaries) in enumerate(studies):
            s = next((s for s in summaries if s.object_set == object_set), None)
            if s is None:
                continue
            margins = [r.counts.margin_pts for r in s.rows if r.counts.pairs]
            ax.plot([x - 0.15] * len(margins), margins, "o", color="tab:blue", alpha=0.6,
                    label="a seed" if x == 0 else None)
            if s.mean_margin_pts is not None:
                low, high = s.interval_pts or (s.mean_margin_pts, s.mean_margin_pts)
                mean = s.mean_margin_pts
                ax.errorbar([x + 0.15], [mean], yerr=[[mean - low], [high - mean]], fmt="D", color="tab:orange",
                            capsize=4, label="mean, 95 % over objects" if x == 0 else None)
                ax.annotate(f"{s.pooled.pairs} pairs", (x + 0.15, high), textcoords="offset points", xytext=(0, 4),
                            ha="center", fontsize=7)
        ax.axhline(0.0, color="black", linewidth=0.8)
        if object_set in PAPER_MARGIN_PTS:
            ax.axhline(PAPER_MARGIN_PTS[object_set], color="grey", linestyle="--", label="paper (five best)")
        ax.set_xticks(range(len(studies)), [label for label, _ in studies], fontsize=8)
        ax.set_xlim(-0.6, len(studies) - 0.4)
        ax.set_title(f"{object_set} set, shake", fontsize=9)
        ax.grid(True, axis="y", linestyle="--", alpha=0.5)
    axes[0][0].set_ylabel("margin, with stiffness - depth only [pts]")
    axes[0][0].legend(fontsize=7, loc="lower left")
    _save(fig, path)
