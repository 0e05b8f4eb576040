"""How much larger a rigid object's collision shape is than its surface (the simulator's one physics, issue 49).

  .venv/bin/python bench/bench_rigid_collision_fidelity.py [--sets train common adversarial] [--objects NAME ...]
      [--resolution 200000] [--max-vertices 32]

A rigid (2e9 Pa) object is a PyBullet rigid body, which must be convex pieces: its collision shape is the V-HACD
decomposition of its surface (sim/meshes.convex_decomposition), in the grasp trials that labelled the training
data and in the cell alike. The camera renders the surface itself (the visual shape), so the planner sees the
surface and the fingers meet the pieces. Per object, the surface and the pieces are ray-cast along horizontal
lines across the object (6 directions over 180 degrees, 5 offsets across a pad's 20 mm, at 25/50/75 % of the
height): the width between the first hits from either end, pieces less surface, is what the pads feel beyond
what was seen. Also the pieces' summed volume against the surface's (overlaps counted twice: an upper bound).
Part of the excess is PyBullet's own: a convex mesh shape carries a collision margin outside its vertices, which
contacts and rays both see (printed first: a 5 cm cube's hull against a sphere, contact distance less the true gap).

Prints one line per object (median and largest width excess over the lines, mm; volume excess, %) and a summary
per set. --resolution / --max-vertices try other V-HACD settings (decompositions are cached per setting).
"""
from __future__ import annotations

import argparse
import math
import sys
from pathlib import Path

import numpy as np
import trimesh

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from defgg_ros.constants import FINGER_PAD_WIDTH_M  # noqa: E402
from defgg_ros.sim import meshes  # noqa: E402
from defgg_ros.sim import objects as sim_objects  # noqa: E402

DIRECTIONS = 6
OFFSETS = 5
HEIGHT_FRACTIONS = (0.25, 0.5, 0.75)
RAY_REACH_M = 0.2


def pieces_volume_m3(obj_path: Path) -> float:
    """Summed volume of the closed convex pieces of a V-HACD .obj (read as one mesh: the signed volumes add)."""
    return abs(float(trimesh.load(obj_path, force="mesh", process=False).volume))


def hull_margin_m() -> float:
    """How much nearer a convex mesh shape's contacts are than its vertices: a 5 cm cube given as a hull of its
    8 corners, the closest-point distance to a sphere 15 mm from its face, less 15 mm (negative: the margin)."""
    import pybullet as p
    client = p.connect(p.DIRECT)
    try:
        h = 0.025
        corners = [[sx * h, sy * h, sz * h] for sx in (-1, 1) for sy in (-1, 1) for sz in (-1, 1)]
        hull = p.createMultiBody(0, p.createCollisionShape(p.GEOM_MESH, vertices=corners, physicsClientId=client),
                                 -1, [0, 0, 0], physicsClientId=client)
        ball = p.createMultiBody(0, p.createCollisionShape(p.GEOM_SPHERE, radius=0.01, physicsClientId=client),
                                 -1, [h + 0.025, 0, 0], physicsClientId=client)
        return 0.015 - p.getClosestPoints(hull, ball, 1.0, physicsClientId=client)[0][8]
    finally:
        p.disconnect(client)


def _widths_m(client: int, body: int, lines) -> np.ndarray:
    """Per (start, end) line through the object: the distance between the first hits from either end (nan: a miss)."""
    import pybullet as p
    starts = [s for s, _ in lines] + [e for _, e in lines]
    ends = [e for _, e in lines] + [s for s, _ in lines]
    hits = p.rayTestBatch(starts, ends, physicsClientId=client)
    n = len(lines)
    out = np.full(n, np.nan)
    for i in range(n):
        a, b = hits[i], hits[n + i]
        if a[0] == body and b[0] == body:
            out[i] = float(np.linalg.norm(np.subtract(a[3], b[3])))
    return out


def _lines(height_m: float) -> list:
    """Horizontal lines across the object (its bounding box centred on the origin, resting on z = 0)."""
    lines = []
    for k in range(DIRECTIONS):
        a = math.pi * k / DIRECTIONS
        along, across = np.array([math.cos(a), math.sin(a), 0.0]), np.array([-math.sin(a), math.cos(a), 0.0])
        for y in np.linspace(-FINGER_PAD_WIDTH_M / 2, FINGER_PAD_WIDTH_M / 2, OFFSETS):
            for f in HEIGHT_FRACTIONS:
                c = across * y + np.array([0.0, 0.0, f * height_m])
                lines.append(((c - RAY_REACH_M * along).tolist(), (c + RAY_REACH_M * along).tolist()))
    return lines


def measure(name: str, resolution: int, max_vertices: int) -> dict:
    """Width excess (mm: median, max over the lines) and volume excess (%) of one object's pieces."""
    import pybullet as p
    surface = sim_objects.get_shape(name).surface()
    lo, hi = surface.bounds
    surface.apply_translation([-(lo[0] + hi[0]) / 2, -(lo[1] + hi[1]) / 2, -lo[2]])
    tet = meshes.tetrahedralize(surface)
    pieces = meshes.convex_decomposition(tet, resolution, max_vertices)
    lines = _lines(float(hi[2] - lo[2]))
    widths = []
    for collision in (dict(fileName=str(tet.obj_path), flags=p.GEOM_FORCE_CONCAVE_TRIMESH),
                      dict(fileName=str(pieces))):
        client = p.connect(p.DIRECT)
        try:
            shape = p.createCollisionShape(p.GEOM_MESH, physicsClientId=client, **collision)
            body = p.createMultiBody(0, shape, -1, [0, 0, 0], physicsClientId=client)
            widths.append(_widths_m(client, body, lines))
        finally:
            p.disconnect(client)
    excess_mm = (widths[1] - widths[0]) * 1e3
    excess_mm = excess_mm[np.isfinite(excess_mm)]
    return {"median_mm": float(np.median(excess_mm)), "max_mm": float(np.max(excess_mm)),
            "volume_pct": 100.0 * (pieces_volume_m3(pieces) / tet.volume_m3 - 1.0), "lines": int(excess_mm.size)}


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0], epilog=__doc__.split("\n\n", 1)[1],
                                     formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--sets", nargs="+", default=["train", "common", "adversarial"], help="object sets")
    parser.add_argument("--objects", nargs="+", help="object names instead of --sets")
    parser.add_argument("--resolution", type=int, default=meshes.VHACD_RESOLUTION, help="V-HACD voxels")
    parser.add_argument("--max-vertices", type=int, default=meshes.VHACD_MAX_VERTICES_PER_PIECE,
                        help="V-HACD vertices per convex piece")
    args = parser.parse_args(argv)
    groups = {"objects": args.objects} if args.objects else {
        s: [shape.name for shape in sim_objects.object_set(s)] for s in args.sets}
    print(f"PyBullet's convex-shape collision margin: {hull_margin_m() * 1e3:.2f} mm a side (contacts nearer "
          "than the hull's vertices)")
    print(f"V-HACD resolution {args.resolution}, <= {args.max_vertices} vertices a piece; width excess = the "
          "pieces' width less the surface's along horizontal lines (mm)")
    for group, names in groups.items():
        rows = []
        for name in names:
            m = measure(name, args.resolution, args.max_vertices)
            rows.append(m)
            print(f"  {group:11s} {name:22s} width excess median {m['median_mm']:5.2f}  max {m['max_mm']:5.2f} mm"
                  f"  volume +{m['volume_pct']:5.1f} %  ({m['lines']} lines)", flush=True)
        med = [r["median_mm"] for r in rows]
        print(f"{group}: {len(rows)} objects, median width excess {np.median(med):.2f} mm (objects' medians "
              f"{min(med):.2f} .. {max(med):.2f}), largest {max(r['max_mm'] for r in rows):.2f} mm; volume "
              f"+{np.median([r['volume_pct'] for r in rows]):.1f} % (median)", flush=True)
    return 0


if __name__ == "__main__":
    sys.exit(main())
