"""A tiny synthetic dataset in the real format, shared by the training tests."""
import pytest

from defgg_ros.data.synthetic import write_synthetic_dataset


@pytest.fixture(scope="session")
def tiny_dataset(tmp_path_factory):
    """3 objects x 4 moduli: one object per split."""
    root = tmp_path_factory.mktemp("tiny_synth")
    write_synthetic_dataset(root, n_objects=3, trials_per_scene=24, seed=2)
    return root
