"""The network: shapes, channel variants, the reference GG-CNN size, config checks."""
import pytest
import torch

from defgg_ros.model.network import GGCNN, GGCNNConfig, build_network, parameter_count


@pytest.mark.parametrize("architecture", ["ggcnn", "ggcnn_bilinear"])
@pytest.mark.parametrize("channels", [1, 2])
def test_output_is_four_full_resolution_maps(architecture, channels):
    net = GGCNN(GGCNNConfig(input_channels=channels, architecture=architecture)).eval()
    with torch.no_grad():
        out = net(torch.zeros(2, channels, 300, 300))
    assert out.shape == (2, 4, 300, 300)
    assert torch.isfinite(out).all()


def test_wrong_channel_count_is_rejected_by_the_network():
    net = GGCNN(GGCNNConfig(input_channels=2))
    with pytest.raises(RuntimeError):
        net(torch.zeros(1, 1, 300, 300))


def test_reference_ggcnn_has_the_published_parameter_count():
    assert parameter_count(GGCNN(GGCNNConfig(input_channels=1, architecture="ggcnn"))) == 62_420


def test_fast_decoder_is_smaller_than_the_reference():
    fast = parameter_count(GGCNN(GGCNNConfig(input_channels=2)))
    ref = parameter_count(GGCNN(GGCNNConfig(input_channels=2, architecture="ggcnn")))
    assert fast < ref


@pytest.mark.parametrize("kwargs", [{"input_channels": 3}, {"architecture": "resnet"},
                                    {"encoder_channels": (8, 8)}])
def test_bad_config_raises(kwargs):
    with pytest.raises(ValueError):
        GGCNNConfig(**kwargs)


def test_config_dict_round_trip():
    config = GGCNNConfig(input_channels=1, decoder_channels=(8, 12))
    assert GGCNNConfig.from_dict(config.to_dict()) == config
    assert build_network(config.to_dict()).config == config
    with pytest.raises(ValueError, match="unknown"):
        GGCNNConfig.from_dict({**config.to_dict(), "dropout": 0.1})
