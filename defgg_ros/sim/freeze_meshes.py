"""Freeze the library objects' tet meshes into the shipped store (meshes.STORE_DIR).

fTetWild gives a slightly different mesh on every run, and a grasp near the
label threshold can flip with the mesh, so the meshes that made a dataset
must be the ones every later run simulates. This copies each library
object's mesh (the local cache's if present, i.e. the one this machine has
been simulating) into the store; meshes already in the store are kept.

  .venv/bin/python -m defgg_ros.sim.freeze_meshes                   # train, common, adversarial
  .venv/bin/python -m defgg_ros.sim.freeze_meshes --max-nodes 220 80
"""
from __future__ import annotations

import argparse

from defgg_ros.sim import library, meshes, objects
from defgg_ros.sim.trimesh_import import trimesh


def surfaces_to_mesh(shape: objects.ObjectShape) -> list:
    """Every surface the simulator tetrahedralizes for this shape: each part, and the union of several."""
    parts = list(shape._surfaces)
    return parts + ([trimesh.util.concatenate(parts)] if len(parts) > 1 else [])


def freeze_sets(set_names, max_nodes_list) -> tuple:
    """(added, kept) counts over the named sets and node bounds."""
    added = kept = 0
    for set_name in set_names:
        for shape in objects.object_set(set_name):
            for surface in surfaces_to_mesh(shape):
                for max_nodes in max_nodes_list:
                    _, new = meshes.freeze(surface, max_nodes)
                    added += new
                    kept += not new
            print(f"{set_name}/{shape.name}", flush=True)
    return added, kept


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--sets", nargs="+", default=sorted(library.OBJECT_SETS), choices=sorted(library.OBJECT_SETS))
    ap.add_argument("--max-nodes", nargs="+", type=int, default=[meshes.TARGET_MAX_NODES],
                    help=f"node bounds to freeze (default {meshes.TARGET_MAX_NODES}, the default mesh)")
    args = ap.parse_args(argv)
    added, kept = freeze_sets(args.sets, args.max_nodes)
    print(f"store {meshes.STORE_DIR}: {added} meshes added, {kept} already there")


if __name__ == "__main__":
    main()
