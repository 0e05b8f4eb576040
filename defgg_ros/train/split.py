"""Split scenes by OBJECT, never by image: every modulus and every augmented
copy of an object lands in the same split, so validation and test objects
are unseen shapes in training."""
from __future__ import annotations

import numpy as np

SPLITS = ("train", "val", "test")


def check_split_fractions(val_fraction: float, test_fraction: float) -> None:
    """ValueError unless both fractions are > 0 and leave objects to train on (sum below 1)."""
    if not (0 < val_fraction and 0 < test_fraction and val_fraction + test_fraction < 1):
        raise ValueError(f"val_fraction and test_fraction must be > 0 with a sum below 1 (the rest trains), "
                         f"got {val_fraction} and {test_fraction}")


def split_objects(object_names, val_fraction: float, test_fraction: float, seed: int) -> dict:
    """{split: sorted object names}; val/test get at least one object each
    when there are at least three objects."""
    names = sorted(set(object_names))
    if len(names) < 3:
        raise ValueError(f"need at least 3 distinct objects to split train/val/test, got {len(names)}")
    check_split_fractions(val_fraction, test_fraction)
    order = np.random.default_rng(seed).permutation(len(names))
    n_val = max(1, round(val_fraction * len(names)))
    n_test = max(1, round(test_fraction * len(names)))
    n_val = min(n_val, len(names) - 2)
    n_test = min(n_test, len(names) - 1 - n_val)
    shuffled = [names[i] for i in order]
    return {"val": sorted(shuffled[:n_val]), "test": sorted(shuffled[n_val:n_val + n_test]),
            "train": sorted(shuffled[n_val + n_test:])}


def fixed_split(object_names, val_objects, test_objects=()) -> dict:
    """{split: sorted object names} with the validation (and test) objects named; every other object trains.
    Keeps a validation set fixed while the data or the rest of the split changes (issue 49: the objects a
    dataset adds, or the test objects moved into training, must not move the validation objects)."""
    names = set(object_names)
    val, test = set(val_objects), set(test_objects)
    unknown = sorted((val | test) - names)
    if unknown:
        raise ValueError(f"split objects {unknown} have no labelled scene in the data; its objects: {sorted(names)}")
    if not val:
        raise ValueError("a fixed split needs at least one validation object")
    if val & test:
        raise ValueError(f"objects both in validation and test: {sorted(val & test)}")
    train = names - val - test
    if not train:
        raise ValueError("a fixed split must leave objects to train on")
    return {"val": sorted(val), "test": sorted(test), "train": sorted(train)}


def split_scenes(scene_objects: dict, object_split: dict) -> dict:
    """scene_objects: {scene_id: object_name} -> {split: sorted scene ids}."""
    where = {name: split for split, names in object_split.items() for name in names}
    out = {split: [] for split in SPLITS}
    for sid, name in sorted(scene_objects.items()):
        out[where[name]].append(sid)
    return out
