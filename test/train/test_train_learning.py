"""A tiny real training run: the loss falls and the rectangle metric rises above chance."""
import math

import numpy as np
import pytest
import torch

from defgg_ros.data.dataset import GraspDataset
from defgg_ros.data.format import GraspRect, list_scene_ids
from defgg_ros.data.synthetic import write_synthetic_dataset
from defgg_ros.grasping.rectangles import rectangle_match
from defgg_ros.model.network import GGCNN, GGCNNConfig
from defgg_ros.train.metrics import grasp_loss, rectangle_accuracy


def chance_accuracy(samples, rng, draws=200) -> float:
    """Rectangle metric of uniformly random grasps ON the object (a generous chance level)."""
    hits = []
    for s in samples:
        vs, us = np.nonzero(s.object_mask)
        for _ in range(draws):
            i = rng.integers(len(us))
            rect = GraspRect(us[i], vs[i], rng.uniform(-math.pi / 2, math.pi / 2), rng.uniform(0, 150),
                             s.positives[0].finger_height_px)
            hits.append(rectangle_match(rect, s.positives))
    return float(np.mean(hits))


@pytest.fixture(scope="module")
def scenes(tmp_path_factory):
    root = tmp_path_factory.mktemp("fit")
    write_synthetic_dataset(root, n_objects=2, trials_per_scene=32, seed=4)
    return GraspDataset(root, list_scene_ids(root))


def test_training_lowers_loss_and_beats_chance(scenes):
    torch.set_num_threads(1)
    torch.manual_seed(0)
    model = GGCNN(GGCNNConfig())
    optimizer = torch.optim.Adam(model.parameters(), lr=3e-3)
    x = torch.stack([scenes[i]["x"] for i in range(len(scenes))])
    y = torch.stack([scenes[i]["y"] for i in range(len(scenes))])
    chance = chance_accuracy(scenes.samples, np.random.default_rng(0))
    before = rectangle_accuracy(model, scenes.samples, True)["accuracy"]
    generator = torch.Generator().manual_seed(0)
    losses, best = [], 0.0
    for step in range(1, 161):
        model.train()
        batch = torch.randperm(len(scenes), generator=generator)[:4]
        loss = grasp_loss(model(x[batch]), y[batch], positive_weight=10.0)["loss"]
        optimizer.zero_grad()
        loss.backward()
        optimizer.step()
        losses.append(float(loss.detach()))
        if step % 20 == 0:
            best = max(best, rectangle_accuracy(model, scenes.samples, True)["accuracy"])
            if best >= 0.5:
                break
    assert np.mean(losses[-10:]) < 0.7 * np.mean(losses[:10])
    assert chance < 0.2 and before <= chance + 0.125, (before, chance)
    assert best >= 0.375 and best > chance + 0.25, (best, chance)
