"""Scene files: every shipped scene parses; bad scenes fail with a message that names the problem."""
from pathlib import Path

import pytest

from defgg_ros.constants import MAX_SOFT_BODY_YOUNGS_MODULUS_PA
from defgg_ros.sim.scene_spec import SceneError, load_scene, parse_scene, scene_warnings

SCENES = Path(__file__).resolve().parents[2] / "sim_bringup" / "scenes"
SESSION_SCENES = SCENES.parent / "sessions" / "scenes"


def _scene(**obj):
    base = {"name": "a", "shape": "box", "size_m": [0.05, 0.05, 0.05], "position_xy_m": [0.5, 0.0],
            "youngs_modulus_pa": 2e9}
    base.update(obj)
    return {"objects": [base]}


@pytest.mark.parametrize("path", sorted([*SCENES.glob("*.yaml"), *SESSION_SCENES.glob("*.yaml")]),
                         ids=lambda p: f"{p.parent.name}/{p.name}")
def test_shipped_scenes_parse(path):
    scene = load_scene(path)
    assert scene.objects
    for obj in scene.objects:
        assert obj.is_soft == (obj.youngs_modulus_pa <= MAX_SOFT_BODY_YOUNGS_MODULUS_PA)


def test_demo_scene_spans_soft_to_rigid():
    moduli = sorted(o.youngs_modulus_pa for o in load_scene(SCENES / "demo.yaml").objects)
    assert len(moduli) >= 4 and moduli[0] <= 2e4 and moduli[-1] >= 2e9
    assert len(set(moduli)) >= 3


@pytest.mark.parametrize("change, words", [
    ({"shape": "blob"}, "shape"),
    ({"size_m": [0.05, -0.01, 0.05]}, "size_m"),
    ({"size_m": [0.05, 0.05]}, "size_m"),
    ({"youngs_modulus_pa": 0}, "youngs_modulus_pa"),
    ({"youngs_modulus_pa": float("nan")}, "youngs_modulus_pa"),
    ({"youngs_modulus_pa": "soft"}, "youngs_modulus_pa"),
    ({"position_xy_m": None}, "position_xy_m"),
    ({"name": ""}, "name"),
    ({"mass_kg": 0}, "mass_kg"),
    ({"poisson_ratio": 0.5}, "poisson_ratio"),
])
def test_bad_object_fields_are_named(change, words):
    with pytest.raises(SceneError, match=words):
        parse_scene(_scene(**change))


def test_non_unit_camera_quaternion_is_rejected():
    raw = _scene()
    raw["base_T_camera"] = {"xyz": [0.5, 0, 0.4], "quat_xyzw": [1, 1, 0, 0]}
    with pytest.raises(SceneError, match="unit quaternion"):
        parse_scene(raw)


def test_duplicate_names_are_rejected():
    raw = _scene()
    raw["objects"].append(dict(raw["objects"][0]))
    with pytest.raises(SceneError, match="unique"):
        parse_scene(raw)


def test_missing_file_and_bad_yaml(tmp_path):
    with pytest.raises(SceneError, match="does not exist"):
        load_scene(tmp_path / "nope.yaml")
    bad = tmp_path / "bad.yaml"
    bad.write_text("objects: [\n")
    with pytest.raises(SceneError, match="YAML"):
        load_scene(bad)


def test_an_object_off_the_table_is_rejected():
    with pytest.raises(SceneError, match="object a: position_xy_m .* is off the table's top"):
        parse_scene(_scene(position_xy_m=[0.5, 0.6]))     # the default table reaches y 0.5 m


@pytest.mark.parametrize("center_y_m, warned", [(-0.45, True), (-0.37, False)])
def test_a_bin_over_the_table_edge_is_warned_about(center_y_m, warned):
    # The default table reaches y -0.5 m; a 0.22 m bin with 1 cm walls reaches 0.12 m from its centre. A
    # warning, not an error: recorded sessions replay the scene they were recorded with.
    raw = _scene()
    raw["bin"] = {"center_xy_m": [0.35, center_y_m], "inner_size_m": [0.22, 0.22, 0.06]}
    warnings = scene_warnings(parse_scene(raw))
    if warned:
        (warning,) = warnings
        assert "bin's walls (x 0.230 ... 0.470 m, y -0.570 ... -0.330 m) reach beyond the table's top" in warning
    else:
        assert warnings == []


@pytest.mark.parametrize("path", sorted([*SCENES.glob("*.yaml"), *SESSION_SCENES.glob("*.yaml")]),
                         ids=lambda p: f"{p.parent.name}/{p.name}")
def test_shipped_scenes_have_nothing_to_warn_about(path):
    assert scene_warnings(load_scene(path)) == []
