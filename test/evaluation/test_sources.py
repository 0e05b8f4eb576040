"""Object sources: named held-out sets and a folder of meshes with a moduli YAML."""
import pytest
import trimesh

from defgg_ros.evaluation import sources


def test_named_sets_are_the_held_out_ones():
    common = sources.named_set("common")
    assert len(common) == 7 and sum(o.multi_material for o in common) == 1
    assert len(sources.named_set("adversarial")) >= 20
    with pytest.raises(sources.SourceError, match="cannot be evaluated"):
        sources.named_set("train")
    with pytest.raises(sources.SourceError, match="no object"):
        sources.named_set("common", only=["not_there"])


def test_multi_material_spec_varies_part_one_only():
    mm = next(o for o in sources.named_set("common") if o.multi_material)
    assert mm.spec(2e5).part_moduli_pa() == [sources.MULTI_MATERIAL_BASE_E_PA, 2e5]


def _write_box(path, size):
    trimesh.creation.box(extents=size).export(path)


def test_mesh_folder_with_yaml(tmp_path):
    _write_box(tmp_path / "block.stl", (0.05, 0.03, 0.04))
    _write_box(tmp_path / "slab.obj", (40.0, 30.0, 20.0))    # millimetres
    (tmp_path / "moduli.yaml").write_text(
        "youngs_modulus_pa: [2.0e4, 2.0e9]\nobjects:\n  slab: {youngs_modulus_pa: [2.0e5], scale: 0.001}\n")
    objs = {o.name: o for o in sources.mesh_folder(tmp_path)}
    assert objs["block"].moduli_pa == (2e4, 2e9)
    assert objs["slab"].moduli_pa == (2e5,) and objs["slab"].mesh_scale == 0.001
    shape = sources.shape_from_ref(objs["slab"].ref)
    assert shape.surface().extents.max() == pytest.approx(0.04, rel=0.05)


def test_mesh_folder_errors(tmp_path):
    with pytest.raises(sources.SourceError, match="no .obj or .stl"):
        sources.mesh_folder(tmp_path)
    _write_box(tmp_path / "block.stl", (0.05, 0.03, 0.04))
    (tmp_path / "moduli.yaml").write_text("objects:\n  ghost: 2e5\n")
    with pytest.raises(sources.SourceError, match="not in"):
        sources.mesh_folder(tmp_path)
    (tmp_path / "moduli.yaml").write_text("objects:\n  block: -5\n")
    with pytest.raises(sources.SourceError, match="block"):
        sources.mesh_folder(tmp_path)
    (tmp_path / "moduli.yaml").write_text("colour: red\n")
    with pytest.raises(sources.SourceError, match="unknown keys"):
        sources.mesh_folder(tmp_path)
    with pytest.raises(sources.SourceError, match="does not exist"):
        sources.mesh_folder(tmp_path, yaml_path=tmp_path / "nope.yaml")
    with pytest.raises(sources.SourceError, match="outside"):
        sources.check_moduli([1e12])


def test_cli_plans_grasps_on_a_mesh_folder(tmp_path, capsys):
    """`defgg-eval run --objects DIR --plan-only`: a user's mesh, moduli from the YAML, real render + both models."""
    import json
    from pathlib import Path

    from defgg_ros.evaluation import cli

    meshes = tmp_path / "meshes"
    meshes.mkdir()
    _write_box(meshes / "block.stl", (0.05, 0.03, 0.04))
    (meshes / "moduli.yaml").write_text("objects:\n  block: [2.0e5, 2.0e9]\n")
    repo = Path(__file__).resolve().parents[2]
    out = tmp_path / "out"
    assert cli.main(["run", "--objects", str(meshes), "--out", str(out), "--plan-only", "--grasps", "2",
                     "--experiments", "main", "--no-progress",
                     "--model", f"defgg_cnn={repo / 'models/defgg_cnn.pt'}",
                     "--model", f"ggcnn_depth_only={repo / 'models/ggcnn_depth_only.pt'}"]) == 0
    plans = json.loads((out / "plans.json").read_text())
    assert {(p["view"]["model"], p["view"]["youngs_modulus_pa"]) for p in plans} == {
        (m, e) for m in ("defgg_cnn", "ggcnn_depth_only") for e in (2e5, 2e9)}
    for p in plans:
        assert p["view"]["object_set"] == "user" and 1 <= len(p["grasps"]) <= 2
        g = p["grasps"][0]
        assert abs(g["position_m"][0]) < 0.05 and abs(g["position_m"][1]) < 0.05 and 0 < g["width_m"] <= 0.08
    manifest = json.loads((out / "run.json").read_text())
    assert manifest["objects"]["user"][0]["moduli_pa"] == [2e5, 2e9]
    # the budget: one simulation per distinct grasp and task, none finished here to cost it
    distinct = {(p["view"]["youngs_modulus_pa"], tuple(round(c, 5) for c in g["position_m"]), round(g["yaw_rad"], 5),
                 round(g["width_m"], 5)) for p in plans for g in p["grasps"]}
    printed = capsys.readouterr().out
    assert "16 trials pending" in printed       # 2 models x 2 moduli x 2 grasps x 2 tasks
    assert f"{2 * len(distinct)} simulations to run" in printed and "no finished simulation here" in printed
