"""Grasps on the generated scenes before and after 'one perceiver' (issue 47.1): identical where perception is
unchanged.

Run in a checkout, it plans the generated scenes in process the way that checkout's nodes do for a request
carrying depth + camera_info (top_k 5, default moduli) and writes, per scene, each grasp's object, pixel
(u, v), image angle, opening and quality (--out). Before the change (no planning/perceived_frame.py) the
inference node perceived the request itself: TabletopPlanner.plan. After it, the segmentation node perceives
(perceive_frame) and the inference node plans on the view rebuilt from its PerceivedObjects
(view_from_parts, moduli_image, TabletopPlanner.network and search). --compare A B prints both side by side
and the largest differences.

    git worktree add /tmp/wt_before <commit before>; git worktree add /tmp/wt_after <commit after>
    (cd /tmp/wt_before && python bench/bench_one_perceiver_grasps.py --out /tmp/before.json)
    (cd /tmp/wt_after && python bench/bench_one_perceiver_grasps.py --out /tmp/after.json)
    python bench/bench_one_perceiver_grasps.py --compare /tmp/before.json /tmp/after.json
"""
import argparse
import json
import math
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
TOP_K = 5


def scenes():
    """(name, rendered frame) of the generated scenes both checkouts have."""
    from defgg_ros.perception import tabletop_scenes as ts

    for width, height, seed in ((640, 480, 7), (848, 480, 5), (1280, 720, 3)):
        yield f"cluttered {width}x{height}", ts.render(ts.cluttered_table(width, height), seed=seed)
    for index, obj in enumerate(ts.cluttered_objects()):
        yield f"overhead {obj.name}", ts.render(ts.overhead_single(obj), seed=index)


def plan_before_or_after(predictor, frame):
    """(path name, grasps) of this checkout's request path."""
    from defgg_ros.perception.tabletop import TabletopConfig
    from defgg_ros.planning.tabletop_planner import TabletopPlanner

    planner = TabletopPlanner(predictor)
    try:
        from defgg_ros.planning.perceived_frame import moduli_image, perceive_frame, view_from_parts
        from defgg_ros.planning.tabletop_planner import PerceivedObjects
    except ImportError:
        return "before: the inference node perceives (TabletopPlanner.plan)", \
            planner.plan(frame.depth_m, frame.camera_k, frame.base_T_camera, TOP_K).grasps
    parts, _, _ = perceive_frame(frame.depth_m, frame.camera_k, frame.base_T_camera, TabletopConfig())
    view = view_from_parts(parts, frame.depth_m, frame.camera_k)
    objects = PerceivedObjects(view, None, moduli_image(parts, frame.depth_m.shape), None)
    prepared = planner.network(objects)
    return "after: the segmentation node perceives, the inference node plans on PerceivedObjects", \
        planner.search(prepared, TOP_K).grasps


def run(out: Path) -> None:
    from defgg_ros.model.inference import GraspPredictor
    from defgg_ros.planning.tabletop_grasps import image_projection

    predictor = GraspPredictor.from_checkpoint(ROOT / "models" / "defgg_cnn.pt", num_threads=1)
    result, path = {}, ""
    for name, frame in scenes():
        try:
            path, grasps = plan_before_or_after(predictor, frame)
        except ValueError as exc:
            result[name] = {"error": str(exc)[:120]}
            continue
        rows = []
        for g in grasps:
            image = image_projection(g, frame.base_T_camera, frame.camera_k)
            rows.append({"object": int(g.object_id), "u_px": float(image["u_px"]), "v_px": float(image["v_px"]),
                         "angle_rad": float(image["angle_rad"]), "width_m": float(g.width_m),
                         "quality": float(g.quality)})
        result[name] = {"grasps": rows}
    out.write_text(json.dumps({"path": path, "scenes": result}, indent=1))
    print(f"{path}: {len(result)} scenes -> {out}")


def compare(a_path: Path, b_path: Path) -> int:
    a, b = json.loads(a_path.read_text()), json.loads(b_path.read_text())
    print(f"A: {a['path']}\nB: {b['path']}")
    print(f"{'scene':28s} {'#':>2s}  {'A: obj (u, v) px, angle deg, width mm':42s}  {'B: same':42s}  differs")
    worst = {"px": 0.0, "deg": 0.0, "mm": 0.0}
    differing = 0
    for name in a["scenes"]:
        ga, gb = a["scenes"][name].get("grasps"), b["scenes"].get(name, {}).get("grasps")
        if ga is None or gb is None:
            same = a["scenes"][name] == b["scenes"].get(name)
            print(f"{name:28s}     A {a['scenes'][name]}  B {b['scenes'].get(name)}  {'' if same else 'YES'}")
            differing += not same
            continue
        for index in range(max(len(ga), len(gb))):
            x = ga[index] if index < len(ga) else None
            y = gb[index] if index < len(gb) else None
            text = [f"{g['object']} ({g['u_px']:.1f}, {g['v_px']:.1f}), {math.degrees(g['angle_rad']):.1f}, "
                    f"{g['width_m'] * 1e3:.1f}" if g else "-" for g in (x, y)]
            same = x == y
            if x and y:
                worst["px"] = max(worst["px"], math.hypot(x["u_px"] - y["u_px"], x["v_px"] - y["v_px"]))
                worst["deg"] = max(worst["deg"], abs(math.degrees(x["angle_rad"] - y["angle_rad"])))
                worst["mm"] = max(worst["mm"], abs(x["width_m"] - y["width_m"]) * 1e3)
            differing += not same
            print(f"{name:28s} {index + 1:2d}  {text[0]:42s}  {text[1]:42s}  {'' if same else 'YES'}")
    total = sum(len(s.get("grasps", [])) or 1 for s in a["scenes"].values())
    print(f"{total - differing} of {total} grasps identical (object, pixel, angle, width, quality bit for bit); "
          f"largest differences: {worst['px']:.3g} px, {worst['deg']:.3g} deg, {worst['mm']:.3g} mm")
    return 0 if differing == 0 else 1


def main(argv=None):
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--out", type=Path, help="write this checkout's grasps here (JSON)")
    parser.add_argument("--compare", type=Path, nargs=2, metavar=("A", "B"), help="compare two --out files")
    args = parser.parse_args(argv)
    if args.compare:
        raise SystemExit(compare(*args.compare))
    if not args.out:
        parser.error("give --out or --compare")
    run(args.out)


if __name__ == "__main__":
    main()
