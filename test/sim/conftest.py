"""Simulation tests share the content-addressed tet-mesh cache (~/.cache/defgg_ros/meshes or
$DEFGG_MESH_CACHE): entries are keyed by a hash of the surface and written atomically, so sharing
is safe and saves fTetWild runs; the cache test itself uses a private folder."""
import pytest


@pytest.fixture
def client():
    import pybullet as p

    from defgg_ros.sim import world

    cid = world.connect()
    yield cid
    p.disconnect(cid)
