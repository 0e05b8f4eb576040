"""Model checkpoints: everything needed to rebuild and trust a network.

A checkpoint is a plain dict of tensors and JSON-like values saved with
``torch.save`` and loaded with ``torch.load(weights_only=True)`` (no pickle
code execution). It holds the state dict, the constructor arguments
(GGCNNConfig), the input encodings (depth and stiffness), the fingerprint of
the training data, a sha256 of the weights (detects tampering/corruption) and
free-form metadata (epoch, metrics, command line). Training-resume state
(optimizer, step) lives in a separate file written by the trainer, so shipped
model files stay small.
"""
from __future__ import annotations

import hashlib
import os
from pathlib import Path

import torch

from defgg_ros.atomic import atomic_path
from defgg_ros.model.network import GGCNN, GGCNNConfig, build_network
from defgg_ros.model.preprocess import DEPTH_ENCODING_NAME, STIFFNESS_ENCODING_NAME

CHECKPOINT_FORMAT = "defgg-checkpoint"
CHECKPOINT_VERSION = 1
_REQUIRED_KEYS = ("format", "version", "network_config", "state_dict", "input_normalization",
                  "data_fingerprint", "weights_sha256", "meta")


class CheckpointError(RuntimeError):
    """A checkpoint is missing, truncated, tampered with or of another format."""


def weights_sha256(state_dict: dict) -> str:
    """Hash of names, dtypes, shapes and bytes of every tensor (sorted by name)."""
    h = hashlib.sha256()
    for name in sorted(state_dict):
        t = state_dict[name].detach().cpu().contiguous()
        h.update(f"{name}|{t.dtype}|{tuple(t.shape)}|".encode())
        h.update(t.numpy().tobytes())
    return h.hexdigest()


def input_normalization(config: GGCNNConfig) -> dict:
    return {"depth": DEPTH_ENCODING_NAME,
            "stiffness": STIFFNESS_ENCODING_NAME if config.input_channels == 2 else None}


def checkpoint_payload(network: GGCNN, data_fingerprint: str, meta: dict | None = None) -> dict:
    state = {k: v.detach().cpu().clone() for k, v in network.state_dict().items()}
    return {
        "format": CHECKPOINT_FORMAT,
        "version": CHECKPOINT_VERSION,
        "network_config": network.config.to_dict(),
        "state_dict": state,
        "input_normalization": input_normalization(network.config),
        "data_fingerprint": str(data_fingerprint),
        "weights_sha256": weights_sha256(state),
        "meta": dict(meta or {}),
    }


def save_checkpoint(path, network: GGCNN, data_fingerprint: str, meta: dict | None = None) -> Path:
    """Write the checkpoint atomically (temp file + rename); return its path."""
    path = Path(path)
    payload = checkpoint_payload(network, data_fingerprint, meta)
    with atomic_path(path) as tmp:
        torch.save(payload, tmp)
        os.chmod(tmp, 0o644)  # mkstemp creates 0600; models are shared files
    return path


def load_checkpoint(path) -> dict:
    """Read and verify a checkpoint; raise CheckpointError with the reason."""
    path = Path(path)
    if not path.is_file():
        raise CheckpointError(f"{path}: checkpoint file not found")
    try:
        payload = torch.load(path, map_location="cpu", weights_only=True)
    except Exception as exc:  # truncated zip, foreign pickle, tampered bytes...
        raise CheckpointError(f"{path}: cannot read checkpoint ({type(exc).__name__}: {exc})") from None
    _check_payload(path, payload)
    return payload


def _check_payload(path, payload) -> None:
    if not isinstance(payload, dict) or payload.get("format") != CHECKPOINT_FORMAT:
        raise CheckpointError(f"{path}: not a {CHECKPOINT_FORMAT} file")
    missing = [k for k in _REQUIRED_KEYS if k not in payload]
    if missing:
        raise CheckpointError(f"{path}: missing entries {missing}")
    if payload["version"] != CHECKPOINT_VERSION:
        raise CheckpointError(f"{path}: version {payload['version']!r}, this code reads {CHECKPOINT_VERSION}")
    if weights_sha256(payload["state_dict"]) != payload["weights_sha256"]:
        raise CheckpointError(f"{path}: weights do not match their sha256 (corrupted or tampered)")
    try:
        config = GGCNNConfig.from_dict(payload["network_config"])
    except (TypeError, ValueError) as exc:
        raise CheckpointError(f"{path}: bad network_config ({exc})") from None
    expected = input_normalization(config)
    if payload["input_normalization"] != expected:
        raise CheckpointError(f"{path}: trained with input encodings {payload['input_normalization']}, "
                              f"this code provides {expected}")


def network_from_checkpoint(payload: dict, path="<checkpoint>") -> GGCNN:
    """Rebuild the network (eval mode) from a verified payload."""
    network = build_network(payload["network_config"])
    try:
        network.load_state_dict(payload["state_dict"], strict=True)
    except RuntimeError as exc:
        raise CheckpointError(f"{path}: weights do not fit the network config ({exc})") from None
    return network.eval()


def make_random_checkpoint(path, uses_stiffness: bool = True, seed: int = 0,
                           architecture: str = GGCNNConfig.architecture, meta: dict | None = None) -> Path:
    """A freshly initialised (untrained) network saved as a checkpoint; meta: more training metadata.

    For tests of the code that consumes checkpoints; its grasps are arbitrary.
    """
    generator_state = torch.random.get_rng_state()
    try:
        torch.manual_seed(seed)
        network = GGCNN(GGCNNConfig(input_channels=2 if uses_stiffness else 1, architecture=architecture))
    finally:
        torch.random.set_rng_state(generator_state)
    return save_checkpoint(path, network, data_fingerprint="untrained",
                           meta={"note": "random initialisation, not trained", "seed": seed, **(meta or {})})
