"""The object sets, by name: "train" (30), "common" (7) and "adversarial" (24).

train = 13 primitives + 5 everyday (YCB-like) + 12 EGAD-style shapes, as in
the paper's training set. common and adversarial are held out for the
evaluation and are never used in training (disjoint names and seeds).
Sizes keep at least one horizontal extent below the 8 cm Panda opening.
Each entry maps a name to a builder returning one list of overlapping
surface pieces per part; only "mallet_mm" has two parts (multi-material).
"""
from __future__ import annotations

from defgg_ros.sim import shapes as s

CM = 0.01


def _primitives() -> dict:
    return {
        "box_small": lambda: [[s.box(5 * CM, 3 * CM, 4 * CM)]],
        "box_flat": lambda: [[s.box(7 * CM, 5 * CM, 2.5 * CM)]],
        "cube": lambda: [[s.box(4 * CM, 4 * CM, 4 * CM)]],
        "cylinder_tall": lambda: [[s.cylinder(4 * CM, 6 * CM)]],
        "cylinder_disc": lambda: [[s.cylinder(6 * CM, 2.5 * CM)]],
        "sphere": lambda: [[s.sphere(5 * CM)]],
        "ellipsoid": lambda: [[s.ellipsoid(7 * CM, 4.5 * CM, 3.5 * CM)]],
        "cone": lambda: [[s.cone(6 * CM, 5 * CM)]],
        "torus": lambda: [[s.torus(8 * CM, 2.2 * CM)]],
        "prism_tri": lambda: [[s.prism(s.regular_polygon(3, 6 * CM), 4 * CM)]],
        "prism_hex": lambda: [[s.prism(s.regular_polygon(6, 5.5 * CM), 3.5 * CM)]],
        "capsule": lambda: [[s.tube_along(s.arc_points(8 * CM, 0.0), 1.7 * CM)]],
        "pyramid": lambda: [[s.cone(7 * CM, 5 * CM, sections=4)]],
    }


def _everyday() -> dict:
    return {
        "ycb_can": lambda: [[s.cylinder(6.6 * CM, 7 * CM, sections=24)]],
        "ycb_bottle": lambda: [[s.lathe([[0, 0], [2.5 * CM, 0], [2.5 * CM, 7 * CM], [1.2 * CM, 9 * CM],
                                         [1.2 * CM, 11 * CM], [0, 11 * CM]])]],
        "ycb_box": lambda: [[s.box(9 * CM, 5 * CM, 3 * CM)]],
        "ycb_banana": lambda: [[s.tube_along(s.arc_points(15 * CM, 1.2), [0.6 * CM, 1.2 * CM, 1.6 * CM, 1.8 * CM,
                                                                          1.8 * CM, 1.8 * CM, 1.6 * CM, 1.2 * CM,
                                                                          0.6 * CM])]],
        "ycb_mug": lambda: [[s.lathe([[0, 0], [4 * CM, 0], [4 * CM, 8 * CM], [3.4 * CM, 8 * CM],
                                      [3.4 * CM, 0.6 * CM], [0, 0.6 * CM]]),
                             _handle()]],
    }


def _handle():
    pts = s.arc_points(7 * CM, 3.0)
    pts = pts[:, [1, 2, 0]]  # bend in the x-z plane, standing beside the cup wall
    pts[:, 0] = 3.9 * CM + pts[:, 0]
    pts[:, 2] += 4 * CM
    return s.tube_along(pts, 0.6 * CM)


def _egad(seed0: int, count: int, prefix: str) -> dict:
    """EGAD-style shapes, complexity grading 1..6 cycling over three families."""
    out = {}
    for i in range(count):
        level = 1 + (i * 6) // count
        seed = seed0 + i
        family = i % 3
        name = f"{prefix}_{i:02d}_c{level}"
        if family == 0:
            out[name] = (lambda seed=seed, level=level: [[s.radial_blob(seed, level, 6 * CM)]])
        elif family == 1:
            out[name] = (lambda seed=seed, level=level: [s.cluster(seed, level + 1, 6 * CM)])
        else:
            out[name] = (lambda seed=seed, level=level: [[s.star_prism(seed, 3 + level, 7 * CM, 3 * CM)]])
    return out


def _common() -> dict:
    return {
        "common_sponge": lambda: [[s.box(9 * CM, 6 * CM, 3 * CM)]],
        "common_can": lambda: [[s.cylinder(6.5 * CM, 9 * CM, sections=24)]],
        "common_ring": lambda: [[s.torus(7.5 * CM, 2 * CM)]],
        "common_toy_bone": lambda: [[s.tube_along(s.arc_points(11 * CM, 0.0), 1.2 * CM),
                                     s.sphere(3 * CM).apply_translation((5 * CM, 1 * CM, 0)),
                                     s.sphere(3 * CM).apply_translation((5 * CM, -1 * CM, 0)),
                                     s.sphere(3 * CM).apply_translation((-5 * CM, 1 * CM, 0)),
                                     s.sphere(3 * CM).apply_translation((-5 * CM, -1 * CM, 0))]],
        "common_ball": lambda: [[s.sphere(6 * CM)]],
        "common_pear": lambda: [[s.lathe([[0, 0], [3 * CM, 1.5 * CM], [3.2 * CM, 3 * CM], [2 * CM, 5 * CM],
                                          [1.6 * CM, 7 * CM], [0, 8 * CM]])]],
        # Multi-material: a rigid-looking handle (part 0) and a head (part 1)
        # whose stiffness can differ, like the paper's object 7.
        "mallet_mm": lambda: [[s.box(9 * CM, 2.2 * CM, 2.2 * CM).apply_translation((-2 * CM, 0, 0))],
                              [s.box(4 * CM, 5 * CM, 4 * CM).apply_translation((4.5 * CM, 0, 0.9 * CM))]],
    }


# Seeds of the held-out EGAD-style set are far from the training ones.
OBJECT_SETS = {
    "train": {**_primitives(), **_everyday(), **_egad(1000, 12, "egad_train")},
    "common": _common(),
    "adversarial": _egad(5000, 24, "egad_test"),
}
