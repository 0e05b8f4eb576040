"""The inference runtime: eager PyTorch or a frozen TorchScript graph.

bench/bench_inference.py measures both (and the reference GG-CNN) in one run;
AUTO_RUNTIME is the one that was faster there. Whatever is chosen must give
the same outputs as eager PyTorch: it is checked on a random input at load
time (and in test/model/test_runtime.py), and eager is used if it differs.
"""
from __future__ import annotations

import copy
import logging
import warnings

import torch

RUNTIMES = ("auto", "eager", "torchscript")
AUTO_RUNTIME = "torchscript"
# Outputs are O(1); float32 reordering of convolutions differs by ~1e-6.
OUTPUT_ATOL = 1e-4
_log = logging.getLogger(__name__)


def torchscript(network: torch.nn.Module, example: torch.Tensor):
    """Trace + freeze (folds weights into the graph, drops Python dispatch), on a channels-last copy
    of the network: oneDNN's convolutions skip their layout conversions, ~30 % less time per forward
    on this cell's CPUs (bench/bench_inference.py). The caller's network is left as it was."""
    channels_last = copy.deepcopy(network).eval().to(memory_format=torch.channels_last)
    with torch.inference_mode(False), torch.no_grad(), warnings.catch_warnings():
        warnings.simplefilter("ignore")
        return torch.jit.freeze(torch.jit.trace(channels_last, example))


def max_output_difference(a, b, example: torch.Tensor) -> float:
    with torch.inference_mode():
        return float((a(example) - b(example)).abs().max())


def compile_for_inference(network: torch.nn.Module, runtime: str = "auto"):
    """Return (callable, runtime name actually used)."""
    if runtime not in RUNTIMES:
        raise ValueError(f"runtime must be one of {RUNTIMES}, got {runtime!r}")
    network.eval()
    wanted = AUTO_RUNTIME if runtime == "auto" else runtime
    if wanted == "eager":
        return network, "eager"
    size = network.config.input_size_px
    generator = torch.Generator().manual_seed(0)
    example = torch.rand(1, network.config.input_channels, size, size, generator=generator) * 2 - 1
    compiled = torchscript(network, example)
    diff = max_output_difference(network, compiled, example)
    if diff > OUTPUT_ATOL:
        if runtime != "auto":
            raise RuntimeError(f"torchscript output differs from eager by {diff:.2e} > {OUTPUT_ATOL}")
        _log.warning("torchscript differs from eager by %.2e; using eager", diff)
        return network, "eager"
    return compiled, "torchscript"
