"""Simulation tests: a private tet-mesh cache per test session (no fixed /tmp paths)."""
import pytest


@pytest.fixture(scope="session", autouse=True)
def mesh_cache(tmp_path_factory):
    mp = pytest.MonkeyPatch()
    path = tmp_path_factory.mktemp("mesh_cache")
    mp.setenv("DEFGG_MESH_CACHE", str(path))
    yield path
    mp.undo()


@pytest.fixture
def client():
    import pybullet as p

    from defgg_ros.sim import world

    cid = world.connect()
    yield cid
    p.disconnect(cid)
