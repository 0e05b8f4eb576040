"""Object library, tet meshes and their cache, materials, user meshes."""
import numpy as np
import pytest
import trimesh

from defgg_ros.sim import meshes, objects, shapes


def test_sets_have_the_papers_sizes_and_are_disjoint():
    train = {s.name for s in objects.object_set("train")}
    common = {s.name for s in objects.object_set("common")}
    adversarial = {s.name for s in objects.object_set("adversarial")}
    assert len(train) == 30
    assert len([n for n in train if n.startswith("egad_")]) == 12
    assert len([n for n in train if n.startswith("ycb_")]) == 5
    assert len(common) == 7 and len(adversarial) >= 20
    assert not (train & common) and not (train & adversarial) and not (common & adversarial)
    multi = [s for s in objects.object_set("common") if len(s.build()) == 2]
    assert [s.name for s in multi] == ["mallet_mm"]


def test_unknown_set_is_a_clear_error():
    with pytest.raises(objects.UnknownObject, match="unknown object set"):
        objects.object_set("test")


def test_tet_mesh_is_coarse_valid_and_cached(monkeypatch, tmp_path):
    monkeypatch.setenv(meshes.MESH_CACHE_ENV, str(tmp_path))
    box = shapes.box(0.05, 0.03, 0.04)
    tet = meshes.tetrahedralize(box)
    assert len(tet.nodes_m) <= meshes.TARGET_MAX_NODES
    assert np.all(meshes.tet_volumes(tet.nodes_m, tet.tets) > 0)        # positively oriented
    assert tet.volume_m3 == pytest.approx(0.05 * 0.03 * 0.04, rel=0.01)
    assert tet.surface().is_watertight
    assert tet.vtk_path.read_text().startswith("# vtk DataFile")

    def must_not_run(*_):
        raise AssertionError("fTetWild ran again although the mesh is cached")

    monkeypatch.setattr(meshes, "_run_ftetwild", must_not_run)
    again = meshes.tetrahedralize(shapes.box(0.05, 0.03, 0.04))
    assert again.content_hash == tet.content_hash and again.vtk_path.parent == tmp_path
    np.testing.assert_array_equal(again.tets, tet.tets)


def test_convex_pieces_are_cached_per_vhacd_setting(monkeypatch, tmp_path):
    """A decomposition made with other V-HACD settings is never taken for these (the cache key names them)."""
    monkeypatch.setenv(meshes.MESH_CACHE_ENV, str(tmp_path))
    tet = meshes.tetrahedralize(objects.get_shape("box_small")._surfaces[0])     # from the store: no fTetWild
    fine = meshes.convex_decomposition(tet, resolution=40000, max_vertices_per_piece=16)
    coarse = meshes.convex_decomposition(tet, resolution=20000, max_vertices_per_piece=4)
    assert fine != coarse and fine.exists() and coarse.exists()
    assert coarse.read_text() != fine.read_text()
    assert meshes.convex_decomposition(tet, resolution=40000, max_vertices_per_piece=16) == fine


def test_the_vtk_always_holds_the_nodes_of_the_npz_it_is_read_with(monkeypatch, tmp_path):
    """Two processes meshing one new surface at once each write the npz (fTetWild is not deterministic): a VTK
    written from the first beside the second's npz made every later soft body fail resetMeshData."""
    monkeypatch.setenv(meshes.MESH_CACHE_ENV, str(tmp_path))
    box = shapes.box(0.05, 0.03, 0.04)
    first = meshes.tetrahedralize(box)
    # the other process's npz lands after this one wrote its VTK: a different mesh of the same surface
    other = meshes.tetrahedralize(box, max_nodes=20)        # surely another node count
    assert len(other.nodes_m) != len(first.nodes_m)
    np.savez_compressed(tmp_path / f"{first.content_hash}.npz", nodes_m=other.nodes_m, tets=other.tets)
    again = meshes.tetrahedralize(box)
    points = next(line for line in again.vtk_path.read_text().splitlines() if line.startswith("POINTS"))
    assert int(points.split()[1]) == len(again.nodes_m) == len(other.nodes_m)
    np.testing.assert_array_equal(again.nodes_m, other.nodes_m)


def test_every_library_object_has_a_shipped_mesh():
    from defgg_ros.sim.freeze_meshes import surfaces_to_mesh

    for set_name in ("train", "common", "adversarial"):
        for shape in objects.object_set(set_name):
            for surface in surfaces_to_mesh(shape):
                key = meshes.mesh_key(surface)
                assert (meshes.STORE_DIR / f"{key}.npz").exists(), f"{set_name}/{shape.name}: no shipped mesh"


def test_library_meshes_come_from_the_store_not_ftetwild(monkeypatch, tmp_path):
    # fTetWild is not deterministic: a fresh run would give other nodes, so equality
    # with the shipped file shows that every machine simulates the same mesh.
    monkeypatch.setenv(meshes.MESH_CACHE_ENV, str(tmp_path))

    def must_not_run(*_):
        raise AssertionError("fTetWild ran for a library object")

    monkeypatch.setattr(meshes, "_run_ftetwild", must_not_run)
    surface = objects.ObjectShape("box_small", "train", objects.get_shape("box_small").build)._surfaces[0]
    tet = meshes.tetrahedralize(surface)
    with np.load(meshes.STORE_DIR / f"{meshes.mesh_key(surface)}.npz") as shipped:
        np.testing.assert_array_equal(tet.nodes_m, shipped["nodes_m"])
        np.testing.assert_array_equal(tet.tets, shipped["tets"])
    assert tet.vtk_path.parent == tmp_path       # derived files go to the cache, never the store


def test_coarsened_and_remeshed_shapes(monkeypatch, tmp_path):
    monkeypatch.setenv(meshes.MESH_CACHE_ENV, str(tmp_path))
    shape = objects.get_shape("cylinder_tall")
    coarse = shape.coarsened(80)
    assert coarse.coarsened(None) is coarse and shape.coarsened(shape.max_tet_nodes) is shape
    assert all(len(t.nodes_m) <= 80 for t in coarse.tet_parts)
    assert len(coarse.tet_parts[0].nodes_m) < len(shape.tet_parts[0].nodes_m)
    other = shape.remeshed("bench1").tet_parts[0]              # an fTetWild run of its own
    assert other.content_hash.endswith("-bench1") and other.vtk_path.parent == tmp_path
    assert other.volume_m3 == pytest.approx(shape.tet_parts[0].volume_m3, rel=0.02)
    with pytest.raises(meshes.MeshError, match="at least 4 nodes"):
        meshes.tetrahedralize(shape._surfaces[0], max_nodes=3)


def test_shapes_rest_on_the_table_and_fit_the_gripper():
    shape = objects.get_shape("ycb_mug")
    nodes = np.vstack([t.nodes_m for t in shape.tet_parts])
    # centred and resting on z = 0 up to fTetWild's envelope (1e-2 of the diagonal, ~1 mm)
    assert nodes[:, 2].min() == pytest.approx(0.0, abs=1e-3)
    assert abs(nodes[:, 0].max() + nodes[:, 0].min()) < 2e-3
    assert np.ptp(nodes[:, 0]) > 0.09            # the handle is there (cup 8 cm + handle)


def test_user_mesh_loads_and_bad_files_raise(tmp_path):
    path = tmp_path / "part.stl"
    shapes.box(40, 30, 20).export(path)          # millimetres, as CAD exports do
    shape = objects.shape_from_mesh_file(path, scale=0.001)
    assert shape.name == "part"
    assert shape.union_tet.volume_m3 == pytest.approx(0.04 * 0.03 * 0.02, rel=0.02)
    with pytest.raises(meshes.MeshError, match="extent"):
        meshes.load_user_mesh(path)               # 40 m without the scale
    (tmp_path / "junk.obj").write_text("this is not a mesh\n")
    with pytest.raises(meshes.MeshError):
        meshes.load_user_mesh(tmp_path / "junk.obj")
    with pytest.raises(meshes.MeshError, match="only .obj and .stl"):
        meshes.load_user_mesh(tmp_path / "x.ply")


def test_materials_are_validated():
    shape = objects.get_shape("cube")
    with pytest.raises(ValueError):
        objects.ObjectSpec(shape, -2e4)
    with pytest.raises(ValueError, match="Poisson"):
        objects.ObjectSpec(shape, 2e4, poisson_ratio=0.5)
    with pytest.raises(objects.UnsupportedMaterial, match="one part"):
        objects.ObjectSpec(shape, 2e4, part_youngs_modulus_pa=2e5).part_moduli_pa()


def test_two_soft_parts_of_different_modulus_are_refused(client):
    from defgg_ros.sim import world

    spec = objects.ObjectSpec(objects.get_shape("mallet_mm"), 2e5, part_youngs_modulus_pa=2e4)
    world.create_world(client, spec.part_moduli_pa())
    with pytest.raises(objects.UnsupportedMaterial, match="one material"):
        objects.load_object(client, spec)


def test_soft_and_rigid_bodies_by_modulus(client):
    from defgg_ros.sim import world

    shape = objects.get_shape("box_small")
    for e, soft in ((2e4, True), (2e9, False)):
        world.create_world(client, [e])
        loaded = objects.load_object(client, objects.ObjectSpec(shape, e))
        assert [pt.soft for pt in loaded.parts] == [soft]
        assert loaded.mass_kg == pytest.approx(0.05 * 0.03 * 0.04 * objects.DEFAULT_DENSITY_KG_M3, rel=0.02)


def test_concatenated_pieces_become_one_volume():
    tube = shapes.tube_along(shapes.arc_points(0.08, 0.0), 0.01)
    ball = shapes.sphere(0.03).apply_translation((0.04, 0, 0))
    tet = meshes.tetrahedralize(trimesh.util.concatenate([tube, ball]))
    assert tet.surface().is_watertight
    assert tet.volume_m3 < tube.volume + ball.volume  # the overlap is counted once


def test_shipped_coarse_meshes_are_coarser_and_keep_the_volume():
    from defgg_ros.data.datagen import COARSE_SIM_MAX_TET_NODES

    for shape in objects.object_set("train"):
        coarse = shape.coarsened(COARSE_SIM_MAX_TET_NODES)
        for fine_part, coarse_part in zip(shape.tet_parts, coarse.tet_parts):
            assert len(coarse_part.nodes_m) <= len(fine_part.nodes_m), shape.name
            # coarsening shrank curved shapes by up to 14 % and collapsed the mug before the volume rule
            assert coarse_part.volume_m3 == pytest.approx(fine_part.volume_m3, rel=0.10), shape.name
