"""The Def-GG-CNN network: a GG-CNN whose input stacks depth (+ stiffness).

Two architectures share one config dataclass:

* ``"ggcnn"``: the reference GG-CNN (Morrison et al. 2018): conv 9x9/32 s3,
  5x5/16 s2, 3x3/8 s2, then transposed convs 3x3/8, 5x5/16, 9x9/32 mirrored
  and 2x2 one-channel heads (62,420 parameters with one input channel).
* ``"ggcnn_bilinear"`` (the default): the same encoder, but the decoder works
  at 1/6 and 1/3 resolution and ends in 1x1 heads followed by bilinear
  upsampling to 300x300, the idea GG-CNN2 uses.

Why (bench/bench_inference.py, see bench/README.md): the reference's last
9x9 transposed conv writes 32 channels at full resolution, ~415 M of its
~530 M multiply-adds, and its forward peaks at ~130 MB of activations (ours
~16 MB), while the outputs are Gaussian-smoothed (sigma 2 px) before peaks
are picked anyway. Decoding at 100x100 and upsampling the 4 output maps is
4-14x faster in the same benchmark run; the rectangle metric of both
architectures trained on the same data is compared in docs/model.md.
GG-CNN2's dilated trunk spends more compute for accuracy (not measured here);
the cell's grasp service budget (p99 <= 15 ms) pointed the other way.

Outputs are raw (linear) maps, as in GG-CNN: quality Q, cos 2phi, sin 2phi
and width / WIDTH_SCALE_PX. Post-processing clips them to their ranges.
"""
from __future__ import annotations

from dataclasses import asdict, dataclass

import torch
import torch.nn.functional as F
from torch import nn

from defgg_ros.constants import NETWORK_INPUT_SIZE_PX

ARCHITECTURES = ("ggcnn", "ggcnn_bilinear")
OUTPUT_NAMES = ("q", "cos", "sin", "width")


@dataclass(frozen=True)
class GGCNNConfig:
    """Every hyper-parameter of the network (stored in checkpoints)."""

    input_channels: int = 2          # 1 = depth only (baseline), 2 = depth + stiffness
    architecture: str = "ggcnn_bilinear"
    encoder_channels: tuple = (32, 16, 8)
    decoder_channels: tuple = (16, 16)  # ggcnn_bilinear only: at 1/6 and 1/3 resolution
    input_size_px: int = NETWORK_INPUT_SIZE_PX

    def __post_init__(self):
        if self.input_channels not in (1, 2):
            raise ValueError(f"input_channels must be 1 (depth) or 2 (depth + stiffness), got {self.input_channels}")
        if self.architecture not in ARCHITECTURES:
            raise ValueError(f"architecture must be one of {ARCHITECTURES}, got {self.architecture!r}")
        # Tuples survive a JSON/checkpoint round trip as lists; normalise.
        object.__setattr__(self, "encoder_channels", tuple(int(c) for c in self.encoder_channels))
        object.__setattr__(self, "decoder_channels", tuple(int(c) for c in self.decoder_channels))
        if len(self.encoder_channels) != 3 or len(self.decoder_channels) != 2:
            raise ValueError("encoder_channels needs 3 entries and decoder_channels 2")

    def to_dict(self) -> dict:
        d = asdict(self)
        d["encoder_channels"] = list(self.encoder_channels)
        d["decoder_channels"] = list(self.decoder_channels)
        return d

    @classmethod
    def from_dict(cls, d: dict) -> GGCNNConfig:
        unknown = set(d) - set(cls.__dataclass_fields__)
        if unknown:
            raise ValueError(f"unknown network config keys {sorted(unknown)}")
        return cls(**d)


class _Encoder(nn.Module):
    """300 -> 100 -> 50 -> 25 px, the GG-CNN encoder."""

    def __init__(self, in_ch: int, ch: tuple):
        super().__init__()
        self.conv1 = nn.Conv2d(in_ch, ch[0], 9, stride=3, padding=3)
        self.conv2 = nn.Conv2d(ch[0], ch[1], 5, stride=2, padding=2)
        self.conv3 = nn.Conv2d(ch[1], ch[2], 3, stride=2, padding=1)

    def forward(self, x):
        x = F.relu(self.conv1(x))
        x = F.relu(self.conv2(x))
        return F.relu(self.conv3(x))


class GGCNN(nn.Module):
    """Input N x C x 300 x 300 -> four maps N x 1 x 300 x 300 (see OUTPUT_NAMES)."""

    def __init__(self, config: GGCNNConfig | None = None):
        super().__init__()
        self.config = config or GGCNNConfig()
        c = self.config
        enc = c.encoder_channels
        self.encoder = _Encoder(c.input_channels, enc)
        if c.architecture == "ggcnn":
            self.up1 = nn.ConvTranspose2d(enc[2], enc[2], 3, stride=2, padding=1, output_padding=1)
            self.up2 = nn.ConvTranspose2d(enc[2], enc[1], 5, stride=2, padding=2, output_padding=1)
            self.up3 = nn.ConvTranspose2d(enc[1], enc[0], 9, stride=3, padding=3, output_padding=1)
            self.heads = nn.ModuleList(nn.Conv2d(enc[0], 1, kernel_size=2) for _ in OUTPUT_NAMES)
        else:
            dec = c.decoder_channels
            self.dec1 = nn.Conv2d(enc[2], dec[0], 3, padding=1)
            self.dec2 = nn.Conv2d(dec[0], dec[1], 3, padding=1)
            # One 1x1 conv with four output channels = the four 1x1 heads.
            self.head = nn.Conv2d(dec[1], len(OUTPUT_NAMES), kernel_size=1)

    def forward(self, x: torch.Tensor) -> torch.Tensor:
        """Return N x 4 x H x W (channels in OUTPUT_NAMES order)."""
        size = x.shape[-2:]
        f = self.encoder(x)
        if self.config.architecture == "ggcnn":
            f = F.relu(self.up1(f))
            f = F.relu(self.up2(f))
            f = F.relu(self.up3(f))
            return torch.cat([h(f) for h in self.heads], dim=1)
        f = F.interpolate(f, scale_factor=2.0, mode="bilinear", align_corners=False)
        f = F.relu(self.dec1(f))
        f = F.interpolate(f, scale_factor=2.0, mode="bilinear", align_corners=False)
        f = F.relu(self.dec2(f))
        # contiguous(): a no-op in training (NCHW); in the channels-last inference graph (model/runtime.py)
        # it makes the output plain NCHW at the cost of a 100x100x4 copy, not a 300x300x4 one later.
        return F.interpolate(self.head(f).contiguous(), size=size, mode="bilinear", align_corners=False)


def parameter_count(model: nn.Module) -> int:
    return sum(p.numel() for p in model.parameters())


def build_network(config: GGCNNConfig | dict | None = None) -> GGCNN:
    if isinstance(config, dict):
        config = GGCNNConfig.from_dict(config)
    return GGCNN(config)
