"""The demo's outputs: the per-object table, summary.json and the picture (pure, no rclpy)."""
import math
from dataclasses import asdict, dataclass, field

import numpy as np

from defgg_ros.atomic import atomic_path, write_json_atomic
from defgg_ros.constants import OFF_TABLE_DEPTH_M


@dataclass
class PickRow:
    name: str
    youngs_modulus_pa: float
    simulated_as: str                 # soft (FEM) | rigid
    grasp_width_m: float = math.nan
    quality: float = math.nan
    phase_reached: str = "not started"
    success: bool = False
    held_after_transfer: bool = False
    in_bin: bool = False              # ground truth after the pick
    final_position_m: tuple | None = None   # ground truth after the pick (base frame)
    failure_reason: str = ""
    sim_duration_s: float = math.nan
    wall_duration_s: float = math.nan
    estimated_mass_kg: float = math.nan   # the inference node's, from the height map (0: not estimated)
    gripper_force_n: float = math.nan     # what the executor closed with (per finger); NaN: it never closed


@dataclass
class FramePanels:
    """What the picture shows for one object: the inputs, the network's map and the grasp."""
    name: str
    depth_m: np.ndarray
    youngs_modulus_pa: np.ndarray
    quality: np.ndarray | None = None          # full-image quality map, NaN outside the crop
    grasp_uv_px: tuple | None = None
    grasp_angle_rad: float = 0.0
    grasp_width_px: float = 0.0
    extra: dict = field(default_factory=dict)


def _yes(flag: bool) -> str:
    return "yes" if flag else "no"


def _number(value: float, spec: str) -> str:
    return "-" if math.isnan(value) else format(value, spec)


def format_table(rows: list) -> str:
    header = f"{'object':<14} {'E (Pa)':>8} {'sim':>5} {'width (mm)':>10} {'quality':>7} {'mass (g)':>8} " \
             f"{'force (N)':>9} {'phase reached':>14} {'held':>5} {'in bin':>6}  note"
    lines = [header, "-" * len(header)]
    for r in rows:
        width = _number(r.grasp_width_m * 1000, ".1f")
        quality = _number(r.quality, ".3f")
        mass, force = _number(r.estimated_mass_kg * 1000, ".0f"), _number(r.gripper_force_n, ".2f")
        lines.append(f"{r.name:<14} {r.youngs_modulus_pa:>8.0e} {r.simulated_as:>5} {width:>10} {quality:>7} "
                     f"{mass:>8} {force:>9} {r.phase_reached:>14} {_yes(r.held_after_transfer):>5} "
                     f"{_yes(r.in_bin):>6}  {_note(r)}")
    return "\n".join(lines)


def _note(r: PickRow) -> str:
    """The failure, or for a pick that succeeded but did not end in the bin, where the object ended."""
    if r.failure_reason or r.in_bin or r.final_position_m is None:
        return r.failure_reason
    x, y, z = r.final_position_m
    if z < -OFF_TABLE_DEPTH_M:
        return f"left the table after the pick: ended at ({x:.2f}, {y:.2f}, {z:.2f}) m"
    return f"ended outside the bin at ({x:.2f}, {y:.2f}, {z:.2f}) m"


def write_summary(path, rows: list, meta: dict) -> dict:
    summary = dict(meta)
    summary["objects"] = [_json_row(r) for r in rows]
    summary["picked_into_bin"] = sum(r.in_bin for r in rows)
    summary["held_after_transfer"] = sum(r.held_after_transfer for r in rows)
    write_json_atomic(path, summary)
    return summary


def _json_row(row: PickRow) -> dict:
    # JSON has no NaN: missing numbers are null.
    return {k: (None if isinstance(v, float) and math.isnan(v) else v) for k, v in asdict(row).items()}


def _draw_grasp(ax, panel: FramePanels):
    if panel.grasp_uv_px is None:
        return
    u, v = panel.grasp_uv_px
    du = math.cos(panel.grasp_angle_rad) * panel.grasp_width_px / 2
    dv = math.sin(panel.grasp_angle_rad) * panel.grasp_width_px / 2
    ax.plot([u - du, u + du], [v - dv, v + dv], "-", color="red", linewidth=2)
    for s in (-1, 1):  # finger pads across the opening direction
        pu, pv = -math.sin(panel.grasp_angle_rad) * 6, math.cos(panel.grasp_angle_rad) * 6
        ax.plot([u + s * du - pu, u + s * du + pu], [v + s * dv - pv, v + s * dv + pv], "-", color="red",
                linewidth=3)


def save_figure(path, panels: list) -> None:
    """One row per object: depth, log10 stiffness, quality map, each with the chosen grasp."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    rows = max(1, len(panels))
    fig, axes = plt.subplots(rows, 3, figsize=(13, 3.4 * rows), squeeze=False)
    for axrow, panel in zip(axes, panels):
        stiff = np.where(panel.youngs_modulus_pa > 0, np.log10(np.maximum(panel.youngs_modulus_pa, 1.0)), np.nan)
        images = [(panel.depth_m, "depth (m)", "viridis_r", None),
                  (stiff, "log10 E (Pa)", "plasma", (3, 10)),
                  (panel.quality if panel.quality is not None else np.full(panel.depth_m.shape, np.nan),
                   "grasp quality", "magma", (0, 1))]
        for ax, (image, title, cmap, limits) in zip(axrow, images):
            shown = ax.imshow(image, cmap=cmap, vmin=None if limits is None else limits[0],
                              vmax=None if limits is None else limits[1])
            fig.colorbar(shown, ax=ax, fraction=0.035)
            ax.set_title(f"{panel.name}: {title}", fontsize=9)
            ax.set_xticks([])
            ax.set_yticks([])
            _draw_grasp(ax, panel)
    for ax in axes[len(panels):].ravel():
        ax.axis("off")
    fig.tight_layout()
    with atomic_path(path) as tmp:
        fig.savefig(tmp, format="png", dpi=80)
    plt.close(fig)
