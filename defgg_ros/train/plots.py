"""Figures of a training run (matplotlib, headless)."""
from __future__ import annotations

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402

from defgg_ros.atomic import atomic_path  # noqa: E402
from defgg_ros.grasping.postprocess import maps_from_network  # noqa: E402
from defgg_ros.model.preprocess import network_input  # noqa: E402
from defgg_ros.train.metrics import raw_outputs  # noqa: E402


def _save(fig, path) -> None:
    with atomic_path(path) as tmp:
        fig.savefig(tmp, format="png", dpi=90)
    plt.close(fig)


def plot_curves(history: list, path) -> None:
    """Train/val loss and validation rectangle accuracy per epoch."""
    epochs = [h["epoch"] for h in history]
    fig, (ax_loss, ax_acc) = plt.subplots(1, 2, figsize=(10, 4))
    ax_loss.plot(epochs, [h["train_loss"] for h in history], label="train")
    ax_loss.plot(epochs, [h["val_loss"] for h in history], label="validation")
    ax_loss.set_xlabel("epoch")
    ax_loss.set_ylabel("loss (sum of 4 MSE)")
    ax_loss.set_yscale("log")
    ax_loss.legend()
    ax_acc.plot(epochs, [h["val_accuracy"] for h in history], label="all moduli", linewidth=2)
    for e in history[-1]["val_per_modulus"] if history else []:
        ax_acc.plot(epochs, [h["val_per_modulus"].get(e, {}).get("accuracy", np.nan) for h in history],
                    label=f"E = {e} Pa", linestyle="--")
    ax_acc.set_xlabel("epoch")
    ax_acc.set_ylabel("rectangle metric (top-1)")
    ax_acc.set_ylim(0, 1)
    ax_acc.legend(fontsize=8)
    fig.tight_layout()
    _save(fig, path)


def plot_stiffness_response(model, sample, moduli_pa, response: dict, path) -> None:
    """Q maps of one validation object at each input modulus + mean |dQ| bars."""
    uses_stiffness = model.config.input_channels == 2
    fig, axes = plt.subplots(1, len(moduli_pa) + 1, figsize=(3.2 * (len(moduli_pa) + 1), 3.4))
    obj = sample.object_mask > 0
    for ax, e in zip(axes, moduli_pa):
        moduli = np.where(obj, e, 0.0).astype(np.float32)
        q = maps_from_network(raw_outputs(model, network_input(sample.depth_m, moduli, uses_stiffness))).q
        ax.imshow(q, vmin=0, vmax=1, cmap="jet")
        ax.contour(obj, levels=[0.5], colors="w", linewidths=0.5)
        ax.set_title(f"Q, E = {e:.0e} Pa", fontsize=9)
        ax.axis("off")
    keys = list(response)
    axes[-1].bar(range(len(keys)), [response[k]["mean_abs_dq"] for k in keys])
    axes[-1].set_xticks(range(len(keys)), keys, fontsize=7)
    axes[-1].set_title("mean |Q - Q(true E)| on object", fontsize=9)
    fig.suptitle(f"stiffness response: {sample.object_name} (true E = {sample.youngs_modulus_pa:.0e} Pa)")
    fig.tight_layout()
    _save(fig, path)
