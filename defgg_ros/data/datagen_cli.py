"""defgg-datagen: generate the stiffness-labelled grasp dataset with PyBullet FEM trials."""
from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path

from defgg_ros.atomic import write_json_atomic, write_text_atomic
from defgg_ros.cli_help import HelpFormatter
from defgg_ros.constants import GRASP_CANDIDATES_PER_OBJECT, GRASP_HEIGHT_RULES, TRAINING_YOUNGS_MODULI_PA
from defgg_ros.data.datagen import (
    COARSE_SIM_MAX_TET_NODES,
    DatagenConfig,
    generate,
    recorded_generator,
    resolve_grasp_height,
)
from defgg_ros.data.format import DatasetError, dataset_fingerprint, seal_trials
from defgg_ros.data.header import recorded_trial_settings
from defgg_ros.data.signal import SignalError, read_trial_records, render_markdown, signal_report, with_shake_from
from defgg_ros.sim.protocol import resolve_protocol
from defgg_ros.sim.trial_settings import TrialSettings
from defgg_ros.stiffness import InvalidYoungsModulus, check_youngs_modulus

# The trial hand of a new dataset: it presses with the grip force as the cell's hand and franka_gripper do (fem_v1-v5
# ran the speed drive, which pressed FEM bodies with ~1 N whatever was asked; docs/dataset.md, "Finger drive").
NEW_DATASET_FINGER_DRIVE = "press"

DESCRIPTION = """\
Generate grasp trials: per object x Young's modulus, render depth/stiffness/mask,
sample ~200 antipodal top-down candidates (collision-filtered, keep up to
--grasps-per-scene), and label each by the shake test (16 directions, 50 m/s^2,
positive if mean held acceleration >= 25 m/s^2).

Resumable: rerunning with the same --out skips finished trials; a killed run
loses only the trials in flight. Trials run in passes of --pass-size per scene
over ALL scenes, so coverage grows evenly.

Example (background, both cores; a new dataset gets the defgraspsim protocol):
  nohup defgg-datagen --out datasets/mine --workers 2 > datasets/mine.log 2>&1 &
Resume fem_v5 (issue 25's dataset) as it was started:
  defgg-datagen --out datasets/fem_v5 --workers 2 --pass-size 1 --grasps-per-scene 36
A resumed dataset keeps its trial settings: if they differ, the error names the --settings to pass.
A sealed dataset (trials/*.jsonl.gz: fem_v1-v4) is finished and never resumed: write a new one.

Trial protocol (--protocol): defgraspsim (default for a new dataset; the paper's labels: zero gravity,
grip force FOS*m*g/mu, fingers held with F/2 each after the pickup, lost when either finger lets go) or
legacy (fem_v1-v4). A resumed dataset keeps its own. docs/dataset.md, "Trial protocols". A new dataset's
hand presses with the grip force as the cell's does (finger_drive "press"; fem_v1-v5 ran the speed drive:
--settings '{"finger_drive": "speed"}' makes such labels).

Signal report (do the labels carry "stiffness changes which grasp is good"?):
  defgg-datagen signal datasets/fem_v4 [--json out.json] [--md out.md] [--png out.png]
Seal a finished dataset (compress its trial files; the fingerprint stays):
  defgg-datagen seal datasets/fem_v4
Re-run a dataset's trials under a changed setting (e.g. the hand pressing as the cell's; relabel --help):
  defgg-datagen relabel datasets/fem_v5 --out datasets/fem_v5_press --settings '{"finger_drive": "press"}'
  defgg-datagen merge datasets/fem_v5 datasets/fem_v5_press --out datasets/fem_v5p
"""


def settings_overrides(text: str) -> dict:
    """--settings: a JSON object of TrialSettings overrides (json.JSONDecodeError, TypeError on bad input)."""
    settings = json.loads(text)
    if not isinstance(settings, dict):
        raise TypeError("--settings must be a JSON object")
    return settings


def build_parser() -> argparse.ArgumentParser:
    ap = argparse.ArgumentParser(prog="defgg-datagen", description=DESCRIPTION, formatter_class=HelpFormatter,
                                 usage="%(prog)s --out DIR [options]   (generate or resume a dataset)\n"
                                       "       %(prog)s signal FOLDER [--json F] [--md F] [--png F]   "
                                       "(its signal report; signal --help)\n"
                                       "       %(prog)s seal FOLDER   (compress a finished dataset)\n"
                                       "       %(prog)s relabel SOURCE --out DIR --settings JSON   "
                                       "(re-run stored trials; relabel --help)\n"
                                       "       %(prog)s merge SOURCE RELABELLED --out DIR   "
                                       "(a dataset with the re-run trials in; merge --help)")
    ap.add_argument("--out", type=Path, required=True, help="dataset folder (created or resumed)")
    ap.add_argument("--object-set", default="train", choices=("train", "common", "adversarial"),
                    help="object library set (default: train; the others are held out for evaluation)")
    ap.add_argument("--objects", nargs="*", default=(), help="only these object names of the set")
    ap.add_argument("--moduli", type=float, nargs="+", default=list(TRAINING_YOUNGS_MODULI_PA),
                    help="Young's moduli in Pa (default: the paper's 2e4 2e5 2e6 2e9)")
    ap.add_argument("--grasps-per-scene", type=int, default=40, help="labelled trials per object x E (max)")
    ap.add_argument("--pass-size", type=int, default=8, help="trials per scene per pass (coverage order)")
    ap.add_argument("--candidates", type=int, default=GRASP_CANDIDATES_PER_OBJECT,
                    help="antipodal candidates sampled per object before the collision filter")
    ap.add_argument("--seed", type=int, default=0, help="seed of sampling (per object/trial seeds derive from it)")
    ap.add_argument("--workers", type=int, default=1, help="parallel worker processes (or Ray CPUs)")
    ap.add_argument("--ray-address", default=None,
                    help="run on a Ray cluster at this address ('auto', 'ray://host:10001') or 'local' to start "
                         "a local Ray instance with --workers CPUs")
    ap.add_argument("--settings", default="{}",
                    help='JSON overrides of TrialSettings, e.g. \'{"shake_ramp_time_s": 0.5}\'')
    ap.add_argument("--sim-max-tet-nodes", type=int, default=0, metavar="N",
                    help="0 (default): the FEM runs on the shipped mesh. N: soft bodies on a coarser mesh of at "
                         "most N nodes (images and grasp candidates keep the shipped mesh). Measured and NOT used "
                         f"for our data: at N={COARSE_SIM_MAX_TET_NODES} it is 6-12x cheaper but flipped 5 of 27 "
                         "soft labels; at N=80, 1.6x cheaper than the shipped mesh with 3 of 55 labels changed "
                         "(bench/README.md). Fixed for the life of a dataset.")
    ap.add_argument("--grasp-height", choices=GRASP_HEIGHT_RULES, default=None,
                    help="TCP height of a candidate: 'executor' (default for a new dataset) = at the height the "
                         "executor derives from the depth image (half the height seen at the grasp centre), the "
                         "contacts found again there, so each label is of the grasp that is later performed "
                         "(docs/archive/notes_height.md); 'contacts' (the datasets up to fem_v3) = at the sampled "
                         "contacts, anywhere on the object's side. Fixed for the life of a dataset: a resumed "
                         "dataset keeps its own rule when this is not given.")
    ap.add_argument("--protocol", choices=("defgraspsim", "legacy"), default=None,
                    help="trial protocol: defgraspsim (default for a new dataset) or legacy (fem_v1-v4); a resumed "
                         "dataset keeps its own when this is not given")
    ap.add_argument("--no-progress", action="store_true", help="no progress bar")
    return ap


def build_signal_parser() -> argparse.ArgumentParser:
    ap = argparse.ArgumentParser(
        prog="defgg-datagen signal", formatter_class=HelpFormatter,
        description="Signal report of a dataset or pilot folder, from its trial records alone: positive rate per "
                    "modulus, within-scene share of the held-acceleration variance, reversal rates and the "
                    "stiffness-aware minus stiffness-blind oracle gap (docs/dataset.md, 'Signal report').")
    ap.add_argument("folder", type=Path,
                    help="a folder with trials/*.jsonl or sealed *.jsonl.gz (a dataset or a pilot)")
    ap.add_argument("--json", type=Path, default=None, help="also write the figures as JSON here")
    ap.add_argument("--md", type=Path, default=None, help="also write the Markdown report here")
    ap.add_argument("--png", type=Path, default=None,
                    help="also draw the report here: held accelerations against the threshold per modulus, the "
                         "within-scene share and the oracle (PNG)")
    ap.add_argument("--title", default=None, help="heading of the Markdown report (default: the folder name)")
    ap.add_argument("--shake-from", type=Path, default=None, metavar="FOLDER",
                    help="the folder's trials simulated only the twist: take each trial's shake from FOLDER's record "
                         "of the same trial id (a try with the same settings; e.g. bench/pilots/d_defgraspsim_twist "
                         "with --shake-from bench/pilots/a_defgraspsim --label shake_and_twist)")
    ap.add_argument("--label", choices=("shake", "shake_and_twist"), default="shake",
                    help="label rule: the dataset's (shake mean >= 25 m/s^2, default) or that and a mean twist "
                         ">= 250 rad/s^2 (needs trials with the twist recorded)")
    return ap


def seal_main(argv) -> int:
    ap = argparse.ArgumentParser(prog="defgg-datagen seal", formatter_class=HelpFormatter,
                                 description="Compress a finished dataset's trial files (trials/*.jsonl -> .jsonl.gz). "
                                             "Records and fingerprint stay the same; a sealed dataset is never "
                                             "resumed.")
    ap.add_argument("folder", type=Path)
    args = ap.parse_args(argv)
    try:
        before = dataset_fingerprint(args.folder)
        n = seal_trials(args.folder)
        after = dataset_fingerprint(args.folder)
    except (DatasetError, OSError) as exc:
        print(f"defgg-datagen seal: error: {exc}", file=sys.stderr)
        return 2
    if before != after:
        print(f"defgg-datagen seal: fingerprint changed ({before} -> {after})", file=sys.stderr)
        return 1
    print(json.dumps({"sealed_files": n, "fingerprint": after}))
    return 0


def signal_main(argv) -> int:
    args = build_signal_parser().parse_args(argv)
    try:
        records = read_trial_records(args.folder)
        if args.shake_from is not None:
            records = with_shake_from(records, read_trial_records(args.shake_from))
        report = signal_report(records, args.label)
    except (SignalError, OSError, ValueError, KeyError) as exc:
        print(f"defgg-datagen signal: error: {exc}", file=sys.stderr)
        return 2
    title = args.title or f"Signal report: {args.folder.name}"
    text = render_markdown(report, title)
    if args.png:
        from defgg_ros.data.signal_figure import signal_figure  # matplotlib: 1.7 s to import, only for --png

        signal_figure(report, records, args.png, title)
    if args.json:
        write_json_atomic(args.json, report)
    if args.md:
        write_text_atomic(args.md, text)
    print(text, end="")
    return 0


def build_relabel_parser() -> argparse.ArgumentParser:
    ap = argparse.ArgumentParser(
        prog="defgg-datagen relabel", formatter_class=HelpFormatter,
        description="Re-run a dataset's stored trials (same objects, poses, grasps and seeds) under changed trial "
                    "settings; new records go to OUT/trials under the source's file names, what changed to "
                    "OUT/relabel.md. The trials most over the speed drive's ceiling run first. Resumable: rerun "
                    "the same command.",
        epilog="Example (the hand pressing with its force, as the cell's; docs/dataset.md 'Finger drive'):\n"
               "  defgg-datagen relabel datasets/fem_v5 --out datasets/fem_v5_press "
               "--settings '{\"finger_drive\": \"press\"}' --workers 2")
    ap.add_argument("source", type=Path, help="the dataset whose trials are re-run (read only)")
    ap.add_argument("--out", type=Path, required=True, help="folder of the new records (created or resumed)")
    ap.add_argument("--settings", required=True,
                    help='JSON TrialSettings overrides, e.g. \'{"finger_drive": "press"}\'')
    ap.add_argument("--max-youngs-modulus-pa", type=float, default=1e7,
                    help="only trials on objects at most this stiff (default 1e7: the FEM bodies, not the 2e9 Pa "
                         "rigid stand-ins)")
    ap.add_argument("--min-grasp-force-n", type=float, default=0.0,
                    help="only trials that asked at least this force a finger (N)")
    ap.add_argument("--limit", type=int, default=None, help="re-run at most this many of the pending trials")
    ap.add_argument("--negatives-only", action="store_true",
                    help="only trials whose stored label is negative (when the change only adds force, a held "
                         "grasp stays held: relabel.md counts positive -> negative among the positives re-run)")
    ap.add_argument("--sample-seed", type=int, default=None, metavar="SEED",
                    help="take the pending trials in a random order seeded so (with --limit: a sample of what is "
                         "left, e.g. beside the ordered run, to see how far down the changes go)")
    ap.add_argument("--workers", type=int, default=1, help="parallel worker processes")
    ap.add_argument("--no-progress", action="store_true", help="no progress bar (a line per 10 %% instead)")
    return ap


def relabel_main(argv) -> int:
    from defgg_ros.data.relabel import RelabelSpec, run

    args = build_relabel_parser().parse_args(argv)
    try:
        settings = settings_overrides(args.settings)
        if not settings:
            raise TypeError("--settings must be a non-empty JSON object (what to change)")
        TrialSettings().with_fields(**settings)
    except (json.JSONDecodeError, TypeError, ValueError) as exc:
        print(f"defgg-datagen relabel: bad --settings: {exc}", file=sys.stderr)
        return 2
    if args.workers < 1 or (args.limit is not None and args.limit < 0):
        print("defgg-datagen relabel: --workers must be >= 1 and --limit >= 0", file=sys.stderr)
        return 2
    spec = RelabelSpec(args.source, args.out, settings, args.max_youngs_modulus_pa, args.min_grasp_force_n)
    try:
        counts = run(spec, workers=args.workers, limit=args.limit, progress=not args.no_progress,
                     sample_seed=args.sample_seed, negatives_only=args.negatives_only)
    except (DatasetError, OSError) as exc:
        print(f"defgg-datagen relabel: error: {exc}", file=sys.stderr)
        return 2
    print(json.dumps(counts))
    print((args.out / "relabel.md").read_text(encoding="utf-8"), end="")
    return 0


def merge_main(argv) -> int:
    from defgg_ros.data.relabel import merge

    ap = argparse.ArgumentParser(
        prog="defgg-datagen merge", formatter_class=HelpFormatter,
        description="Write a whole dataset: SOURCE with every trial RELABELLED re-ran (defgg-datagen relabel) "
                    "replaced by its new record; its header's trial settings are the relabel's, and its 'relabel' "
                    "section counts the trials that kept their source record (every record carries its settings).")
    ap.add_argument("source", type=Path, help="the dataset the relabel read")
    ap.add_argument("relabelled", type=Path, help="the relabel's --out folder")
    ap.add_argument("--out", type=Path, required=True, help="the new dataset folder (must not exist)")
    args = ap.parse_args(argv)
    try:
        counts = merge(args.source, args.relabelled, args.out)
    except (DatasetError, OSError, KeyError) as exc:
        print(f"defgg-datagen merge: error: {exc}", file=sys.stderr)
        return 2
    print(json.dumps({**counts, "fingerprint": dataset_fingerprint(args.out)}))
    return 0


def main(argv=None) -> int:
    argv = sys.argv[1:] if argv is None else list(argv)
    if argv[:1] == ["relabel"]:
        return relabel_main(argv[1:])
    if argv[:1] == ["merge"]:
        return merge_main(argv[1:])
    if argv[:1] == ["signal"]:
        return signal_main(argv[1:])
    if argv[:1] == ["seal"]:
        return seal_main(argv[1:])
    args = build_parser().parse_args(argv)
    try:
        settings = settings_overrides(args.settings)
        stored = recorded_generator(args.out)       # a resumed dataset keeps its protocol
        recorded = None if stored is None else recorded_trial_settings(stored).to_record()
        settings.setdefault("protocol", resolve_protocol(args.protocol, recorded=recorded).name)
        # a new dataset's hand presses as the cell's; a resumed one keeps its own drive (none recorded: speed)
        settings.setdefault("finger_drive", NEW_DATASET_FINGER_DRIVE if stored is None
                            else recorded_trial_settings(stored).protocol.finger_drive)
        TrialSettings().with_fields(**settings)  # validate names and values now, not in a worker
    except (json.JSONDecodeError, TypeError, ValueError) as exc:
        print(f"defgg-datagen: bad --settings: {exc}", file=sys.stderr)
        return 2
    if 0 < args.sim_max_tet_nodes < 4 or args.sim_max_tet_nodes < 0:
        print("defgg-datagen: --sim-max-tet-nodes must be 0 (shipped mesh) or >= 4 (a tetrahedron)",
              file=sys.stderr)
        return 2
    if args.grasps_per_scene < 1 or args.pass_size < 1 or args.workers < 1 or args.candidates < 1:
        print("defgg-datagen: --grasps-per-scene, --pass-size, --workers and --candidates must be >= 1",
              file=sys.stderr)
        return 2
    try:
        for e in args.moduli:
            check_youngs_modulus(e)
    except InvalidYoungsModulus as exc:
        print(f"defgg-datagen: --moduli: {exc}", file=sys.stderr)
        return 2
    try:
        cfg = DatagenConfig(out=args.out, object_set=args.object_set, objects=tuple(args.objects),
                            moduli_pa=tuple(args.moduli), grasps_per_scene=args.grasps_per_scene,
                            pass_size=args.pass_size, n_candidates=args.candidates, seed=args.seed,
                            workers=args.workers, ray_address=args.ray_address, settings=settings,
                            sim_max_tet_nodes=args.sim_max_tet_nodes or None,
                            grasp_height=resolve_grasp_height(args.out, args.grasp_height))
        counts = generate(cfg, progress_bar=not args.no_progress)
    except DatasetError as exc:
        print(f"defgg-datagen: error: {exc}", file=sys.stderr)
        return 2
    print(json.dumps(counts))
    return 0


if __name__ == "__main__":
    sys.exit(main())
