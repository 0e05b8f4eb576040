"""defgg-eval: the paper's simulation experiments with the shipped models, and their reports.

Examples::

    # both models, held-out common + adversarial sets, 5 best grasps, shake + twist, 2 workers
    defgg-eval run --out results/my_eval --workers 2
    # the same under a dataset's own trial protocol (success = its labels' rule)
    defgg-eval run --out results/my_eval_v5 --workers 2 --protocol-from datasets/fem_v5
    # a folder of meshes, moduli from DIR/moduli.yaml (or --moduli)
    defgg-eval run --objects my_meshes/ --moduli 2e5 2e9 --out results/my_meshes
    defgg-eval report --out results/my_eval        # tables, plots, summary.json (--docs FILE: the Markdown report)
    defgg-eval strategy --object common_toy_bone --out results/my_eval
    # a retrained pair: models/retrain_pair.sh runs freeze, training, ship and card in order
    defgg-eval freeze --data datasets/mine --archive runs/train_data_mine.tar.gz --extract-to runs/frozen_mine
    defgg-eval ship --run runs/defgg --name defgg_cnn --command "defgg-train ..." --wall-s 540 --models-dir runs/ship
    defgg-eval snapshot --name defgg_cnn --out runs/defgg_cnn_train_data.tar.gz
    defgg-eval card --name defgg_cnn --eval results/my_eval --models-dir runs/ship

The shipped reports are results/sim_vN (docs/results.md is rebuilt from the newest by results/run_budgeted_eval.sh).
"""
from __future__ import annotations

import argparse
import json
import shlex
import sys
import tarfile
from pathlib import Path

from defgg_ros.atomic import only_writer, read_jsonl, write_json_atomic, write_text_atomic
from defgg_ros.cli_help import HelpFormatter, use_for
from defgg_ros.constants import EVAL_GRASPS_PER_OBJECT, GRASP_HEIGHT_RULES, TRAINING_YOUNGS_MODULI_PA
from defgg_ros.data.format import DatasetError, check_header
from defgg_ros.evaluation import ceiling, diagnose, docs, runner, sources, strategy
from defgg_ros.evaluation import jobs as jobs_mod
from defgg_ros.evaluation import report as report_mod
from defgg_ros.evaluation.budget import budget_lines
from defgg_ros.evaluation.report import ReportError
from defgg_ros.evaluation.runner import PLANS_FILE, eval_trial_settings
from defgg_ros.evaluation.seeds import seeds_markdown, summarise
from defgg_ros.evaluation.store import ResultsError, read_results, results_path
from defgg_ros.evaluation.tasks import TASKS
from defgg_ros.provenance import git_commit
from defgg_ros.sim import world
from defgg_ros.sim.protocol import TrialProtocol, resolve_protocol
from defgg_ros.sim.trial_settings import TrialSettings, protocol_differences

SEEDS_FIGURE = "seeds.png"    # the report's figure of the seed studies, in its evaluation folder

# Imported inside the commands that need them: the modules that load torch (model.*, evaluation.cards and
# .snapshot, data.dataset: ~1.3 CPU-s over this module's own imports, 2026-11-29), so `defgg-eval --help` and
# the commands that never load a model start without it.

# The subcommands import torch (the model, the cards) and the simulator (the runner, the ceiling) inside their
# functions, so `defgg-eval report` and --help answer without loading them (python -X importtime on the shared
# machine, 2026-11-29: torch 18 s, defgg_ros.sim.trial 2.8 s; sim.trial 0.9 s when the machine was quieter).

DEFAULT_MODELS = ("defgg_cnn=models/defgg_cnn.pt", "ggcnn_depth_only=models/ggcnn_depth_only.pt")


def _add_run(sub):
    p = sub.add_parser(
        "run", formatter_class=HelpFormatter,
        help="plan the models' grasps and run them in the FEM simulator (resumable)",
        description="For each object and Young's modulus, render the scene with the training camera, take each "
                    "model's N best grasps and run them in the PyBullet FEM simulator under the shake task (16 "
                    "directions; under the defgraspsim protocol, the default, success is the label's own rule: "
                    "the mean held acceleration >= 25 m/s^2 with each direction ramped to 50, and 'held at 25 "
                    "in every direction' is the second table; under legacy, held at 25 m/s^2 in all) and the "
                    "twist task (angular acceleration "
                    "oscillating at 40 rad/s, amplitude ramped to 500 rad/s^2; success if held at 500 rad/s^2 "
                    "about all 6 axes). Both models see the same objects, poses and seeds. Each finished "
                    "trial is one fsync'd line of OUT/trials.jsonl: rerunning the same command skips finished "
                    "trials, and a kill (even SIGKILL) loses only the trials in flight.",
        epilog="Trial order is rank-major (every object's best grasp first), so a stopped run covers all cells "
               "evenly; the tables say how many trials are behind each cell.")
    p.add_argument("--out", required=True, help="evaluation folder (results, tables, figures)")
    p.add_argument("--model", action="append", metavar="NAME=PATH", default=None,
                   help=f"a model checkpoint to evaluate (repeatable; default: {' '.join(DEFAULT_MODELS)})")
    p.add_argument("--sets", nargs="+", default=list(sources.EVAL_SETS), choices=sources.EVAL_SETS,
                   help="held-out object sets of the simulator's library (default: %(default)s)")
    p.add_argument("--only", nargs="+", metavar="OBJECT", help="restrict the named sets to these objects")
    p.add_argument("--objects", metavar="DIR", help="evaluate every .obj/.stl in DIR instead of the named sets")
    p.add_argument("--moduli-yaml", metavar="FILE", help="per-mesh moduli/scales for --objects "
                   "(default: DIR/moduli.yaml if present; see defgg_ros/evaluation/sources.py)")
    p.add_argument("--moduli", nargs="+", type=float, default=list(TRAINING_YOUNGS_MODULI_PA), metavar="PA",
                   help="Young's moduli in Pa, the table rows (default: the paper's %(default)s)")
    p.add_argument("--grasps", type=int, default=EVAL_GRASPS_PER_OBJECT,
                   help="best grasps per object and modulus (default %(default)s, as in the paper)")
    p.add_argument("--ranks", type=int, default=None, metavar="R",
                   help="budget: simulate only each view's R best grasps in this invocation (the tables still "
                        "count --grasps per cell, so they show what is missing); rerun with a larger R to continue")
    p.add_argument("--tasks", nargs="+", default=list(TASKS), choices=TASKS, help="default: %(default)s")
    p.add_argument("--experiments", nargs="+", default=list(jobs_mod.EXPERIMENTS), choices=jobs_mod.EXPERIMENTS,
                   help="main tables, stiffness-error sensitivity (stiffness models, shake), multi-material "
                        "(default: %(default)s)")
    p.add_argument("--multimaterial-moduli", nargs="+", type=float, default=list(jobs_mod.MULTIMATERIAL_SOFT_PART_PA),
                   metavar="PA", help="true moduli of the soft part of two-part objects (default %(default)s)")
    p.add_argument("--seed", type=int, default=0, help="seed of the object poses (default %(default)s)")
    p.add_argument("--workers", type=int, default=1, help="simulator worker processes (default %(default)s)")
    p.add_argument("--max-trials", type=int, default=None, help="stop after simulating this many trials")
    p.add_argument("--report-every", type=int, default=10, metavar="N",
                   help="rewrite the tables every N finished trials (default %(default)s)")
    p.add_argument("--quick", action="store_true",
                   help="smoke test only: 5x faster acceleration ramps, shorter lift (recorded in run.json and every "
                        "trial; not the paper's protocol, never for reported numbers)")
    _add_protocol_args(p)
    p.add_argument("--plan-only", action="store_true",
                   help="only render and plan every view's grasps into OUT/plans.json (no simulation; cheap), "
                        "for the diagnostics of the report; prints how many simulations a run would still need "
                        "per task and modulus, and their CPU-hours where OUT holds finished ones to cost them")
    p.add_argument("--no-progress", action="store_true", help="no progress bars")


def _add_protocol_args(p):
    """--protocol and --protocol-from (run and ceiling: resolve_protocol reads both)."""
    p.add_argument("--protocol", choices=("defgraspsim", "legacy"), default=None,
                   help="trial protocol (docs/dataset.md, 'Trial protocols'): defgraspsim (default for a new folder) "
                        "or legacy (results up to sim_v4); a folder being resumed keeps its own")
    p.add_argument("--protocol-from", metavar="DATASET", default=None,
                   help="the trial protocol setting of this dataset's labels (protocol, friction, Poisson's ratio, "
                        "finger hold, grip force rule), so success is the label's own criterion; wins over "
                        "--protocol")


def _add_others(sub):
    p = sub.add_parser("report", help="rewrite tables, plots and summary.json (and the Markdown report)",
                       description="Rewrite OUT/tables/*, OUT/summary.json and, with --docs, the Markdown report "
                                   "from OUT/trials.jsonl and OUT/run.json. Safe while a run is going on.")
    p.add_argument("--out", required=True, help="evaluation folder")
    p.add_argument("--docs", metavar="FILE", help="also write the Markdown report (e.g. docs/results.md)")
    p.add_argument("--notes", metavar="FILE", help="hand-written analysis to include in the report verbatim")
    p.add_argument("--data", metavar="DIR", help="training dataset: add label diagnostics (OUT/diagnostics.json)")
    p.add_argument("--seeds", nargs="+", action="append", metavar="SEED=OUT", default=None,
                   help="with --docs: add the seed study's table over these folders (as `defgg-eval seeds --run`); "
                        "give --seeds again for another study (another dataset's pair), one table each")
    p.add_argument("--cell", metavar="DIR", default=None,
                   help="with --docs: add the cell experiment's report from DIR/report.md (defgg-cell-experiment)")

    p = sub.add_parser("strategy", help="strategy figure: quality map and best grasp at a low and a high E")
    p.add_argument("--out", required=True, help="evaluation folder (writes strategy.png and strategy.json)")
    p.add_argument("--model", default=DEFAULT_MODELS[0], metavar="NAME=PATH", help="default: %(default)s")
    p.add_argument("--object", default="common_toy_bone", help="object of the common/adversarial set")
    p.add_argument("--moduli", nargs=2, type=float, default=[2e4, 2e9], metavar="PA", help="low and high E")
    p.add_argument("--seed", type=int, default=0)

    p = sub.add_parser("ship", help="copy a training run's best checkpoint to models/ with its provenance")
    p.add_argument("--run", required=True, help="defgg-train --out folder (finished)")
    p.add_argument("--name", required=True, help="model name, e.g. defgg_cnn -> models/defgg_cnn.pt")
    p.add_argument("--command", dest="train_command", required=True,
                   help="the training command as run (recorded in the card)")
    p.add_argument("--wall-s", type=float, required=True, help="training wall time in seconds")
    p.add_argument("--commit", default=None, help="git commit of the training code (default: current HEAD)")
    p.add_argument("--checkpoint", choices=("best", "last"), default="best",
                   help="best validation epoch (best.pt) or the last epoch (model.pt) (default %(default)s)")
    p.add_argument("--note", default="", help="why this checkpoint/data, shown in the card")
    p.add_argument("--data-source", default="", help="where the (frozen) training data came from, for the card")
    p.add_argument("--data-archive", default="", help="the shipped archive of the training data, for the card")
    p.add_argument("--models-dir", default="models")

    p = sub.add_parser("freeze", help="freeze a growing dataset before training both models on identical data",
                       description="Cut the dataset to its complete trial records now, write it as a .tar.gz "
                                   "(verified fingerprint) and extract it for training; both models are then "
                                   "trained on the extracted copy, so they see exactly the same trials.")
    p.add_argument("--data", required=True, nargs="+",
                   help="growing dataset root(s) (defgg-datagen --out); several roots with disjoint scenes are "
                        "merged (the first one's dataset.json is kept, frozen_from.json lists all)")
    p.add_argument("--archive", required=True, help="archive to write, e.g. models/train_data_fem_v1.tar.gz")
    p.add_argument("--extract-to", required=True, help="folder to extract the frozen copy into (e.g. runs/)")

    p = sub.add_parser("snapshot", help="freeze a shipped model's training data (dataset cut to its manifest)")
    p.add_argument("--name", required=True, help="shipped model whose models/<name>.train.json to use")
    p.add_argument("--out", required=True, help="archive to write, e.g. models/train_data_fem_v1.tar.gz")
    p.add_argument("--models-dir", default="models")

    p = sub.add_parser(
        "ceiling", help="run the sampler's candidates (not a model's) under a task: random-pick and best-case "
                        "success per modulus, the bounds of any model in this simulator",
        description="For each object of the sets and each modulus, the training data's antipodal sampler proposes "
                    "collision-free candidates; each runs under the task's evaluation protocol. OUT/ceiling.md "
                    "gives per modulus the success of a random candidate and the share of objects where any "
                    "candidate succeeds (resumable: OUT/ceiling.jsonl).")
    p.add_argument("--out", required=True, help="folder for ceiling.jsonl and ceiling.md")
    p.add_argument("--sets", nargs="+", default=["common"], choices=sources.EVAL_SETS, help="default: %(default)s")
    p.add_argument("--only", nargs="+", metavar="OBJECT", help="restrict the sets to these objects")
    p.add_argument("--moduli", nargs="+", type=float, default=list(TRAINING_YOUNGS_MODULI_PA), metavar="PA")
    p.add_argument("--candidates", type=int, default=8,
                   help="candidates per object; the table covers the first this many (default %(default)s)")
    p.add_argument("--task", default="shake", choices=TASKS)
    p.add_argument("--seed", type=int, default=0, help="sampler seed (default %(default)s, the training data's)")
    p.add_argument("--sim-max-tet-nodes", type=int, default=None, metavar="N",
                   help="simulate on a coarser FEM mesh of at most N nodes (default: the shipped mesh)")
    p.add_argument("--grasp-height", choices=GRASP_HEIGHT_RULES, default="contacts",
                   help="candidates at their contacts' height (default, as the training data up to fem_v3) or at "
                        "the height the evaluation executes a model's grasp at (comparable to the models; use a "
                        "new --out folder)")
    p.add_argument("--max-trials", type=int, default=None, help="stop after simulating this many trials")
    _add_protocol_args(p)
    p.add_argument("--summary-only", action="store_true", help="only rewrite OUT/ceiling.md")

    p = sub.add_parser("seeds", help="the seed study: each seed's paired margin, the mean with a bootstrap "
                                     "interval over objects, the pooled tests (over objects; over pairs)")
    p.add_argument("--run", required=True, nargs="+", metavar="SEED=OUT",
                   help="a seed's evaluation folder, e.g. 0=results/sim_v5 1=results/sim_v5_s1")
    p.add_argument("--sets", nargs="+", default=["common", "adversarial"], help="default: %(default)s")
    p.add_argument("--task", default="shake", choices=TASKS)
    p.add_argument("--out", default=None, metavar="FILE", help="also write the Markdown table here")
    p.add_argument("--png", default=None, metavar="FILE",
                   help="also draw it: each seed's margin, the mean and its interval, per object set")

    p = sub.add_parser("card", help="(re)write models/<name>.md from its provenance, weights and evaluation")
    p.add_argument("--name", required=True, nargs="+")
    p.add_argument("--eval", default=None, metavar="OUT", help="evaluation folder whose summary.json to include")
    p.add_argument("--seeds", default=None, metavar="DIR",
                   help="the seed study's weights folder (results/seeds): list what the other seeds gave")
    p.add_argument("--seed-runs", nargs="+", default=None, metavar="SEED=OUT",
                   help="with --seeds: each seed's evaluation folder (as `defgg-eval seeds --run`), so the card "
                        "also shows each seed's margin in the simulator")
    p.add_argument("--models-dir", default="models")


def build_parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(prog="defgg-eval", formatter_class=HelpFormatter,
                                     description=__doc__.split("\n\n")[0], epilog=__doc__.split("\n\n", 1)[1])
    sub = parser.add_subparsers(dest="command", required=True)
    _add_run(sub)
    _add_others(sub)
    return use_for(parser)


def parse_pairs(specs, option: str = "--model", form: str = "NAME=PATH") -> dict:
    """['a=x', 'b=y'] -> {'a': 'x', 'b': 'y'}; a malformed pair or a name given twice is refused by name."""
    out = {}
    for spec in specs:
        name, sep, value = spec.partition("=")
        if not sep or not name or not value:
            raise ValueError(f"{option} expects {form}, got {spec!r}")
        if name in out:
            raise ValueError(f"{option}: {name!r} given twice")
        out[name] = value
    return out


def load_predictors(model_paths: dict) -> dict:
    import torch

    from defgg_ros.model.inference import GraspPredictor

    torch.set_num_threads(1)
    return {name: GraspPredictor.from_checkpoint(path) for name, path in model_paths.items()}


def eval_objects(args) -> list:
    if args.objects:
        return sources.mesh_folder(args.objects, args.moduli, args.moduli_yaml)
    objs = []
    for s in args.sets:
        only = [o for o in args.only if o in {sh.name for sh in sources.sim_objects.object_set(s)}] \
            if args.only else None
        if args.only and not only:
            continue
        objs += sources.named_set(s, args.moduli, only)
    if not objs:
        raise sources.SourceError(f"no object of {args.sets} matches --only {args.only}")
    return objs


def build_views(args, predictors, objects) -> list:
    models = list(predictors)
    stiff = [m for m in models if predictors[m].uses_stiffness]
    views = []
    if "main" in args.experiments:
        views += jobs_mod.main_views(models, objects)
    if "sensitivity" in args.experiments:
        common = [o for o in objects if o.set_name in ("common", "user")]
        views += jobs_mod.sensitivity_views(stiff, common)
    if "multimaterial" in args.experiments:
        views += jobs_mod.multimaterial_views(models, objects, sources.check_moduli(args.multimaterial_moduli))
    return views


def write_manifest(out_dir, args, model_paths, predictors, objects, argv, settings: TrialSettings) -> None:
    by_set = {}
    for o in objects:
        by_set.setdefault(o.set_name, []).append({"name": o.name, "moduli_pa": list(o.moduli_pa),
                                                  "multi_material": o.multi_material})
    manifest = {
        "command": "defgg-eval " + " ".join(shlex.quote(a) for a in argv), "commit": git_commit(),
        "models": {n: {"path": model_paths[n], "sha": p.fingerprint, "uses_stiffness": bool(p.uses_stiffness),
                       "data_fingerprint": p.checkpoint_meta.get("data_fingerprint")} for n, p in predictors.items()},
        "objects": by_set, "grasps_per_object": args.grasps, "tasks": list(args.tasks),
        "experiments": list(args.experiments), "seed": args.seed,
        "sensitivity_errors_pct": list(jobs_mod.SENSITIVITY_ERRORS_PCT),
        "multimaterial_moduli_pa": list(args.multimaterial_moduli),
        "trial_settings": settings.to_record(), "quick": bool(args.quick),
    }
    write_json_atomic(Path(out_dir) / report_mod.MANIFEST_FILE, merge_manifest(out_dir, manifest))


def protocol_of_run(out_dir, requested: str | None, records_file: str | None = None,
                    from_dataset: str | None = None) -> TrialProtocol:
    """The trial protocol of a run, by the one resolver (sim.protocol.resolve_protocol) from what it needs: the
    dataset's header (`from_dataset`: the labels' own protocol, material and grip force), the requested name,
    the settings of the folder's first trial record (a record without one: legacy)."""
    dataset_setting = recorded = None
    if from_dataset is not None:
        dataset_setting = check_header(from_dataset).get("generator", {}).get("trial_settings")
        if not dataset_setting:
            raise ValueError(f"{from_dataset} records no trial settings (its header has only the generator's "
                             "overrides): pass --protocol")
    path = Path(out_dir) / records_file if records_file else results_path(out_dir)
    if requested is None and dataset_setting is None and path.is_file():
        recorded = next((r.get("trial_settings") or {} for r in read_jsonl(path)), None)
    return resolve_protocol(requested, recorded=recorded, dataset_setting=dataset_setting)


def check_same_protocol(out_dir, settings: TrialSettings, tasks) -> None:
    """Trials of one folder share one protocol per task: finished trials are skipped by key, so a run
    with other trial settings (e.g. another lift time) would silently mix them. Only what a task reads is
    compared (sim.trial_settings.task_protocol): a new twist ramp leaves the shake trials."""
    path = results_path(out_dir)
    if not path.is_file():
        return
    records = read_results(path)
    for task in tasks:
        differ = protocol_differences(records, settings.to_record(), task)
        if differ:
            raise ValueError(f"{out_dir} holds {task} trials of another protocol (differs in "
                             f"{', '.join(differ)}); evaluate into a new --out folder")


def merge_manifest(out_dir, manifest: dict) -> dict:
    """Several runs into one folder (e.g. multi-material first, then the main tables) with the same models:
    the folder's manifest is their union, so the report covers everything they ran."""
    path = Path(out_dir) / report_mod.MANIFEST_FILE
    if not path.is_file():
        return {**manifest, "commands": [manifest["command"]], "commits": [manifest["commit"]]}
    old = json.loads(path.read_text(encoding="utf-8"))
    same_models = {n: m["sha"] for n, m in old.get("models", {}).items()} == \
        {n: m["sha"] for n, m in manifest["models"].items()}
    # (a folder of another trial protocol never gets here: check_same_protocol refuses it)
    if not same_models or old.get("grasps_per_object") != manifest["grasps_per_object"] \
            or old.get("seed") != manifest["seed"]:
        return {**manifest, "commands": [manifest["command"]],     # a different evaluation: start the manifest anew
                "commits": [manifest["commit"]]}
    objects = {s: {o["name"]: o for o in objs} for s, objs in old["objects"].items()}
    for s, objs in manifest["objects"].items():
        for o in objs:
            prev = objects.setdefault(s, {}).get(o["name"])
            moduli = sorted(set(o["moduli_pa"]) | set(prev["moduli_pa"] if prev else []))
            objects[s][o["name"]] = {**o, "moduli_pa": moduli}
    return {**manifest, "objects": {s: list(objs.values()) for s, objs in objects.items()},
            "tasks": [t for t in TASKS if t in set(old["tasks"]) | set(manifest["tasks"])],
            "experiments": [e for e in jobs_mod.EXPERIMENTS if e in set(old["experiments"]) | set(
                manifest["experiments"])],
            "multimaterial_moduli_pa": sorted(set(old.get("multimaterial_moduli_pa", [])) | set(
                manifest["multimaterial_moduli_pa"])),
            "commands": list(dict.fromkeys(old.get("commands", [old["command"]]) + [manifest["command"]])),
            # Every code commit a run into this folder started from, oldest first: a resumed evaluation's
            # trials come from several (the last one alone would claim them all).
            "commits": list(dict.fromkeys(old.get("commits", [old["commit"]]) + [manifest["commit"]]))}


def check_run_counts(args) -> None:
    """ValueError naming the first count option out of range (before any model is loaded)."""
    for flag, value, least in (("--grasps", args.grasps, 1), ("--workers", args.workers, 1),
                               ("--ranks", args.ranks, 1), ("--max-trials", args.max_trials, 0),
                               ("--report-every", args.report_every, 1)):
        if value is not None and value < least:
            raise ValueError(f"{flag} must be >= {least}, got {value}")


EVAL_LOCK_FILE = ".eval.lock"


def cmd_run(args, argv) -> int:
    check_run_counts(args)
    model_paths = parse_pairs(args.model or DEFAULT_MODELS)
    predictors = load_predictors(model_paths)
    objects = eval_objects(args)
    Path(args.out).mkdir(parents=True, exist_ok=True)
    # One writer per folder: two runs (a restart while the first still runs, a --plan-only beside a run) would
    # append each trial twice and cut the other's unfinished last line.
    busy = ResultsError(f"{args.out} is being written by another defgg-eval run (it holds "
                        f"{Path(args.out) / EVAL_LOCK_FILE}): wait for it to finish or stop it, then run this again")
    with only_writer(Path(args.out) / EVAL_LOCK_FILE, busy):
        return _run_locked(args, argv, model_paths, predictors, objects)


def _run_locked(args, argv, model_paths, predictors, objects) -> int:
    protocol = protocol_of_run(args.out, args.protocol, from_dataset=args.protocol_from)
    settings = runner.quick_trial_settings(protocol) if args.quick else runner.eval_trial_settings(protocol)
    check_same_protocol(args.out, settings, args.tasks)
    write_manifest(args.out, args, model_paths, predictors, objects, argv, settings)
    plan = runner.EvalPlan(objects, predictors, build_views(args, predictors, objects), args.grasps,
                           tuple(args.tasks), args.seed, settings, args.ranks)
    if args.plan_only:

        path, budget = runner.write_plans(plan, args.out, not args.no_progress)
        print(path)
        print("\n".join(budget_lines(budget)))
        return 0
    counts = runner.run_evaluation(plan, args.out, args.workers, not args.no_progress, args.max_trials,
                                   on_progress=_reporter(args.out, args.report_every))
    report_mod.write_outputs(args.out)
    if counts["errors"]:
        print(f"{counts['errors']} trial(s) raised (see {Path(args.out) / runner.ERRORS_FILE}); "
              "they are retried when this command runs again", file=sys.stderr)
    print(json.dumps(counts))
    return 0


def _reporter(out_dir, every: int):
    def on_progress(n_done: int) -> None:
        if every > 0 and n_done % every == 0:
            report_mod.write_outputs(out_dir)
    return on_progress


def cmd_report(args) -> int:

    summary = report_mod.write_outputs(args.out)
    write_diagnostics(args.out, args.data)
    if args.docs:
        studies = [parse_pairs(group, "--seeds", "SEED=OUT") for group in args.seeds or []]
        summaries = [seed_summaries(runs, ("common", "adversarial")) for runs in studies]
        figure = None
        if studies:
            from defgg_ros.evaluation.figures import seeds_figure  # matplotlib: only when drawn
            figure = Path(args.out) / SEEDS_FIGURE
            seeds_figure([(docs.study_label(runs), s) for runs, s in zip(studies, summaries)], figure)
        tables = [seeds_markdown(s) for s in summaries]
        docs.write_results_doc(args.out, args.docs, args.notes, list(zip(studies, tables)), args.cell, figure)
    print(json.dumps({"records": summary["records"], "targets": summary["targets"]}, indent=1))
    return 0


def write_diagnostics(out_dir, data_root) -> None:
    """OUT/diagnostics.json + .md from the training labels (if --data), OUT/plans.json (if present), the
    repeatability of the folder's trials (if it ran the sensitivity experiment) and how well the
    predicted quality ranks each view's grasps (if it ran more than one rank)."""

    out_dir = Path(out_dir)
    path = out_dir / "diagnostics.json"
    old = json.loads(path.read_text()) if path.is_file() else {}
    labels = diagnose.label_stats(data_root) if data_root else old.get("labels")
    plans_path = out_dir / PLANS_FILE
    shifts = diagnose.plan_shifts(json.loads(plans_path.read_text())) if plans_path.is_file() else None
    results = results_path(out_dir)
    records = read_results(results) if results.is_file() else []
    replicates, ranking = diagnose.replicate_flips(records), diagnose.quality_ranking(records)
    twist_axes, model_pairs = diagnose.twist_by_axis(records), diagnose.model_grasp_pairs(records)
    if all(v is None for v in (labels, shifts, replicates, ranking, twist_axes, model_pairs)):
        return
    write_json_atomic(path, {"labels": labels, "data_root": str(data_root or old.get("data_root")),
                             "plan_shifts": shifts, "replicates": replicates, "quality_ranking": ranking,
                             "twist_by_axis": twist_axes, "model_grasp_pairs": model_pairs})

    write_text_atomic(out_dir / "diagnostics.md", diagnose.diagnostics_markdown(labels, shifts, replicates, ranking,
                                                                                    twist_axes, model_pairs))


def cmd_strategy(args) -> int:

    (name, path), = parse_pairs([args.model]).items()
    predictor = load_predictors({name: path})[name]
    obj = next((o for s in sources.EVAL_SETS for o in sources.named_set(s) if o.name == args.object), None)
    if obj is None:
        raise sources.SourceError(f"no object {args.object!r} in the sets {sources.EVAL_SETS}")
    client = world.connect()
    panels, described = strategy.strategy_panels(predictor, obj, args.moduli, client, args.seed)
    out = Path(args.out)
    strategy.write_strategy_figure(panels, described, out / "strategy.png", obj.name, name)
    write_json_atomic(out / "strategy.json", {"model": name, "model_sha": predictor.fingerprint,
                                              "object": obj.name, "seed": args.seed, "best_grasps": described})
    print(json.dumps({e: d[0] if d else None for e, d in described.items()}, indent=1))
    return 0


def cmd_ship(args) -> int:
    from defgg_ros.evaluation import cards

    prov = cards.training_provenance(args.run, args.train_command, args.wall_s, args.commit or git_commit())
    prov.update(data_source=args.data_source, data_archive=args.data_archive, note=args.note)
    print(cards.ship_model(args.run, args.name, args.models_dir, prov, args.checkpoint))
    return 0


def cmd_snapshot(args) -> int:
    from defgg_ros.evaluation import cards, snapshot

    prov = json.loads((Path(args.models_dir) / f"{args.name}{cards.PROVENANCE_SUFFIX}").read_text())
    path = snapshot.write_snapshot(prov["data_root"], prov["manifest"], prov["data_fingerprint"], args.out)
    print(f"{path} ({path.stat().st_size / 1e6:.2f} MB, fingerprint {prov['data_fingerprint']} verified)")
    return 0


def cmd_freeze(args) -> int:
    from defgg_ros.data.dataset import build_manifest, manifest_fingerprint
    from defgg_ros.evaluation import snapshot

    parts = []
    for root in args.data:
        # Only scenes that have trials: a scene without any is no training data (and may be re-rendered).
        manifest = {sid: n for sid, n in build_manifest(root).items() if n > 0}
        parts.append((root, manifest, manifest_fingerprint(root, manifest)))
    path, fingerprint = snapshot.write_merged_snapshot(parts, args.archive)
    with tarfile.open(path, "r:gz") as tar:
        tar.extractall(args.extract_to, filter="data")
    root = Path(args.extract_to) / "train_data"
    print(json.dumps({"archive": str(path), "size_mb": round(path.stat().st_size / 1e6, 3), "data": str(root),
                      "trials": sum(sum(m.values()) for _, m, _ in parts),
                      "scenes": sum(len(m) for _, m, _ in parts), "fingerprint": fingerprint}))
    return 0


def cmd_ceiling(args, argv) -> int:

    if not args.summary_only:
        sources.check_moduli(args.moduli)
        shapes = [sh for s in args.sets for sh in sources.sim_objects.object_set(s)
                  if not args.only or sh.name in args.only]
        if not shapes:
            raise sources.SourceError(f"no object of {args.sets} matches --only {args.only}")
        trials = ceiling.plan_trials(shapes, args.moduli, args.candidates, args.task, args.seed,
                                     args.sim_max_tet_nodes, args.grasp_height)
        ceiling.record_command(args.out, "defgg-eval " + " ".join(shlex.quote(a) for a in argv))
        protocol = protocol_of_run(args.out, args.protocol, ceiling.RESULTS_FILE, args.protocol_from)
        ceiling.run(args.out, trials, args.task, eval_trial_settings(protocol), args.max_trials,
                    progress=lambda n, total, key: print(f"[{n}/{total}] {key}", flush=True),
                    grasp_height=args.grasp_height)
    print(ceiling.write_table(args.out, args.candidates))
    return 0


def cmd_card(args) -> int:
    from defgg_ros.evaluation import cards

    seed_table = None
    if args.seed_runs:
        if args.seeds is None:
            raise ValueError("--seed-runs needs --seeds (the seed study's weights folder)")
        runs = parse_pairs(args.seed_runs, "--seed-runs", "SEED=OUT")
        seed_table = seeds_markdown(seed_summaries(runs, ("common", "adversarial")))
    for name in args.name:
        print(cards.write_card(name, args.models_dir, args.eval, args.seeds, seed_table))
    return 0


def seed_summaries(seed_runs: dict, sets, task: str = "shake") -> list:
    """The seed study over {seed: evaluation folder}, a summary per object set, each folder read once."""
    runs = {seed: report_mod.current_records(out) for seed, out in seed_runs.items()}
    return [summarise(runs, s, task) for s in sets]


def cmd_seeds(args) -> int:

    seed_runs = parse_pairs(args.run, "--run", "SEED=OUT")
    summaries = seed_summaries(seed_runs, args.sets, args.task)
    table = seeds_markdown(summaries)
    print(table, end="")
    if args.out:
        write_text_atomic(args.out, table)
    if args.png:
        from defgg_ros.evaluation.figures import seeds_figure  # matplotlib: only when drawn
        seeds_figure([(docs.study_label(seed_runs), summaries)], args.png)
    return 0


def main(argv=None) -> int:
    argv = sys.argv[1:] if argv is None else list(argv)
    args = build_parser().parse_args(argv)
    # torch (~1.3 CPU-s at import, measured over this module's own imports): only once a command runs, so
    # `defgg-eval --help` and the commands that never load a model start without it.
    from defgg_ros.evaluation.cards import CardError
    from defgg_ros.evaluation.snapshot import SnapshotError
    from defgg_ros.model.checkpoint import CheckpointError

    try:
        if args.command == "run":
            return cmd_run(args, argv)
        if args.command == "ceiling":
            return cmd_ceiling(args, argv)
        commands = {"report": cmd_report, "strategy": cmd_strategy, "ship": cmd_ship, "card": cmd_card,
                    "snapshot": cmd_snapshot, "freeze": cmd_freeze, "seeds": cmd_seeds}
        return commands[args.command](args)
    except (sources.SourceError, ReportError, ResultsError, CardError, CheckpointError, SnapshotError, DatasetError,
            OSError, ValueError) as exc:
        print(f"defgg-eval: error: {exc}", file=sys.stderr)
        return 2


if __name__ == "__main__":
    sys.exit(main())
