"""Checkpoints: round trip and every way a file can be untrustworthy."""
import pytest
import torch

from defgg_ros.model.checkpoint import (
    CheckpointError,
    load_checkpoint,
    make_random_checkpoint,
    network_from_checkpoint,
    save_checkpoint,
)
from defgg_ros.model.network import GGCNN, GGCNNConfig
from defgg_ros.stiffness import ENCODING_NAME


def test_round_trip_gives_identical_outputs(tmp_path):
    torch.manual_seed(3)
    net = GGCNN(GGCNNConfig(input_channels=2)).eval()
    path = save_checkpoint(tmp_path / "m.pt", net, data_fingerprint="abc123", meta={"epoch": 4})
    payload = load_checkpoint(path)
    assert payload["data_fingerprint"] == "abc123"
    assert payload["meta"] == {"epoch": 4}
    assert payload["input_normalization"]["stiffness"] == ENCODING_NAME
    rebuilt = network_from_checkpoint(payload)
    x = torch.randn(1, 2, 300, 300)
    with torch.no_grad():
        assert torch.equal(net(x), rebuilt(x))
    assert rebuilt.config == net.config


def test_depth_only_checkpoint_records_no_stiffness_encoding(tmp_path):
    payload = load_checkpoint(make_random_checkpoint(tmp_path / "d.pt", uses_stiffness=False))
    assert payload["network_config"]["input_channels"] == 1
    assert payload["input_normalization"]["stiffness"] is None


def test_random_checkpoints_are_seeded(tmp_path):
    a = load_checkpoint(make_random_checkpoint(tmp_path / "a.pt", seed=1))
    b = load_checkpoint(make_random_checkpoint(tmp_path / "b.pt", seed=1))
    c = load_checkpoint(make_random_checkpoint(tmp_path / "c.pt", seed=2))
    assert a["weights_sha256"] == b["weights_sha256"] != c["weights_sha256"]


def test_missing_file(tmp_path):
    with pytest.raises(CheckpointError, match="not found"):
        load_checkpoint(tmp_path / "nope.pt")


def test_truncated_file(tmp_path):
    path = make_random_checkpoint(tmp_path / "t.pt")
    data = path.read_bytes()
    path.write_bytes(data[: len(data) // 2])
    with pytest.raises(CheckpointError, match="cannot read"):
        load_checkpoint(path)


def test_tampered_weights_are_detected(tmp_path):
    path = make_random_checkpoint(tmp_path / "w.pt")
    payload = torch.load(path, weights_only=True)
    payload["state_dict"]["encoder.conv1.weight"][0, 0, 0, 0] += 1.0
    torch.save(payload, path)
    with pytest.raises(CheckpointError, match="sha256"):
        load_checkpoint(path)


def test_other_format_and_wrong_encoding(tmp_path):
    torch.save({"state_dict": {}}, tmp_path / "other.pt")
    with pytest.raises(CheckpointError, match="not a defgg-checkpoint"):
        load_checkpoint(tmp_path / "other.pt")
    path = make_random_checkpoint(tmp_path / "e.pt")
    payload = torch.load(path, weights_only=True)
    payload["input_normalization"]["stiffness"] = "linear_v0"
    torch.save(payload, path)
    with pytest.raises(CheckpointError, match="encodings"):
        load_checkpoint(path)


class _Evil:
    def __reduce__(self):
        return (print, ("code ran",))


def test_pickled_objects_are_refused(tmp_path):
    torch.save({"format": "defgg-checkpoint", "x": _Evil()}, tmp_path / "evil.pt")
    with pytest.raises(CheckpointError, match="cannot read"):
        load_checkpoint(tmp_path / "evil.pt")
