"""Re-run a dataset's stored trials under changed trial settings (defgg-datagen relabel): the same objects, poses,
grasps and seeds (data.datagen.job_from_record), a setting changed (e.g. {"finger_drive": "press"}: the hand
presses as the cell's does, sim/finger_press.py). New records go to OUT/trials/ under the source's file names, so
`defgg-datagen signal OUT` and the trainer read them; OUT/relabel.json records what was asked.

Order: the trials asking most above the speed drive's ceiling first (hand.speed_drive_ceiling_n: what a
speed-driven finger presses an FEM body with at most), so a stopped run's prefix holds the trials most likely to
change. Resumable: a rerun skips the trial ids OUT already holds; a
trial that raised goes to OUT/trial_errors.jsonl and is retried by the next run.
"""
from __future__ import annotations

import contextlib
import json
import multiprocessing as mp
import random
import shutil
from dataclasses import dataclass
from pathlib import Path

from tqdm import tqdm

from defgg_ros.atomic import append_jsonl, only_writer, read_jsonl, write_json_atomic, write_text_atomic
from defgg_ros.data.card import write_card
from defgg_ros.data.datagen import job_from_record, run_trial_job_guarded
from defgg_ros.data.format import TRIAL_ERRORS_FILE, DatasetError, TrialRecord, dataset_fingerprint
from defgg_ros.data.signal import render_markdown, signal_report
from defgg_ros.sim.hand import speed_drive_ceiling_n
from defgg_ros.sim.physics import time_step_for
from defgg_ros.sim.trial_settings import TrialSettings

HEADER_FILE = "relabel.json"
LOCK_FILE = ".relabel.lock"     # held while a run writes: two runs into one folder would re-run each other's trials
REPORT_FILE = "relabel.md"
RELABELLED_STATUSES = ("ok", "lift_failed")     # the trials with a label; an exploded or timed-out one has none
# Bands of asked force / the speed drive's ceiling (report).
CEILING_BANDS = (0.0, 0.5, 0.7, 0.9, 1.1, 1.5, 2.0, float("inf"))


@dataclass(frozen=True)
class RelabelSpec:
    source: Path
    out: Path
    settings: dict                    # TrialSettings overrides (stored names)
    max_youngs_modulus_pa: float      # only trials on objects this soft or softer (FEM bodies: < 1e7)
    min_grasp_force_n: float = 0.0    # only trials whose hand was asked for at least this force a finger

    def header(self) -> dict:
        return {"source": str(self.source), "source_fingerprint": dataset_fingerprint(self.source),
                "settings": self.settings, "max_youngs_modulus_pa": self.max_youngs_modulus_pa,
                "min_grasp_force_n": self.min_grasp_force_n}


def source_trials(source: Path) -> dict:
    """{file name: its records} of a dataset's trial files (plain or sealed)."""
    folder = Path(source) / "trials"
    files = sorted(folder.glob("*.jsonl")) + sorted(folder.glob("*.jsonl.gz"))
    if not files:
        raise DatasetError(f"no trial files in {folder}")
    return {f.name.removesuffix(".gz"): read_jsonl(f) for f in files}


def over_ceiling(record: dict) -> float:
    """The force a trial asked a finger for / what its speed-driven hand could press with (>1: it got less)."""
    settings = TrialSettings.from_record(record["sim"].get("settings") or {})
    step_s = settings.motion.time_step_s or time_step_for([record["youngs_modulus_pa"]])
    return record["grasp_force_n"] / speed_drive_ceiling_n(step_s, settings.motion.close_speed_mps)


def eligible(spec: RelabelSpec, record: dict) -> bool:
    """Does the spec re-run this stored trial?"""
    return (record["status"] in RELABELLED_STATUSES and record["youngs_modulus_pa"] <= spec.max_youngs_modulus_pa
            and record["grasp_force_n"] >= spec.min_grasp_force_n)


def selected(spec: RelabelSpec, by_file: dict) -> list:
    """(file name, record) of the trials to re-run, the most over the ceiling first."""
    chosen = [(name, r) for name, records in by_file.items() for r in records if eligible(spec, r)]
    return sorted(chosen, key=lambda item: (-over_ceiling(item[1]), item[1]["trial_id"]))


def relabel_job(record: dict, overrides: dict) -> dict:
    job = job_from_record(TrialRecord.from_json(record))
    job["settings"] = TrialSettings.from_record(job["settings"]).with_fields(**overrides).to_record()
    return job


def relabelled_records(out: Path) -> list:
    """Every complete record a relabel folder holds (its trials/*.jsonl)."""
    return [r for f in sorted((Path(out) / "trials").glob("*.jsonl")) for r in read_jsonl(f)]


def done_ids(out: Path) -> set:
    return {r["trial_id"] for r in relabelled_records(out)}


def check_or_write_header(spec: RelabelSpec) -> None:
    path = spec.out / HEADER_FILE
    header = spec.header()
    if path.exists():
        stored = json.loads(path.read_text(encoding="utf-8"))
        if stored != header:
            differ = sorted(k for k in header if stored.get(k) != header[k])
            raise DatasetError(f"{spec.out} relabels with other {', '.join(differ)} ({path}); use another --out")
        return
    write_json_atomic(path, header)


def run(spec: RelabelSpec, workers: int = 1, limit: int | None = None, progress: bool = True,
        sample_seed: int | None = None, negatives_only: bool = False) -> dict:
    """Re-run the selected trials not yet in OUT; returns counts. sample_seed: in a seeded random order instead
    (with `limit`, a sample of what is left: how the labels change over the whole range, before the ordered run
    gets there; its records are the same trials' and the ordered run skips them). negatives_only: only trials
    whose stored label is negative (a change that only adds force cannot drop a held grasp; measured, not assumed:
    relabel.md counts positive -> negative among the positives re-run)."""
    TrialSettings().with_fields(**spec.settings)          # a bad setting is refused before anything runs
    by_file = source_trials(spec.source)
    spec.out.mkdir(parents=True, exist_ok=True)
    check_or_write_header(spec)
    have = done_ids(spec.out)
    pending = [(name, r) for name, r in selected(spec, by_file) if r["trial_id"] not in have
               and not (negatives_only and _label(r) is not False)]
    if sample_seed is not None:
        random.Random(sample_seed).shuffle(pending)
    pending = pending[:limit] if limit is not None else pending
    file_of = {r["trial_id"]: name for name, r in pending}
    jobs = [relabel_job(r, spec.settings) for _, r in pending]
    counts = {"pending": len(jobs), "done": 0, "errors": 0}
    busy = DatasetError(f"another defgg-datagen relabel is writing {spec.out}; let it finish or stop it")
    writer = only_writer(Path(spec.out) / LOCK_FILE, busy) if jobs else contextlib.nullcontext()
    with writer, tqdm(total=len(jobs), desc="relabel", unit="trial", disable=not progress, smoothing=0.05) as bar:
        for result in _results(jobs, workers):
            if "error" in result:
                append_jsonl(spec.out / TRIAL_ERRORS_FILE, result)
                counts["errors"] += 1
                bar.write(f"trial {result['trial_id']} raised {result['error']} (in {TRIAL_ERRORS_FILE})")
                continue
            append_jsonl(spec.out / "trials" / file_of[result["trial_id"]], result)
            counts["done"] += 1
            bar.update(1)
            if not progress and counts["done"] % max(1, len(jobs) // 10) == 0:
                print(f"defgg-datagen relabel: {counts['done']} of {len(jobs)} trials", flush=True)
    write_text_atomic(spec.out / REPORT_FILE, render_report(spec, by_file))
    return counts


def _results(jobs: list, workers: int):
    if workers <= 1:
        for job in jobs:
            yield run_trial_job_guarded(job)
        return
    with mp.get_context("spawn").Pool(workers, maxtasksperchild=50) as pool:
        yield from pool.imap_unordered(run_trial_job_guarded, jobs, chunksize=1)


def label_changes(by_file: dict, out: Path) -> list:
    """(stored record, new record) of every trial OUT has re-run."""
    stored = {r["trial_id"]: r for records in by_file.values() for r in records}
    return [(stored[r["trial_id"]], r) for r in relabelled_records(out) if r["trial_id"] in stored]


def _label(record: dict):
    return TrialRecord.from_json(record).label


def render_report(spec: RelabelSpec, by_file: dict) -> str:
    """Labels that changed, per modulus and per band of asked force."""
    pairs = label_changes(by_file, spec.out)
    planned = sum(eligible(spec, r) for records in by_file.values() for r in records)
    lines = [f"# Relabel of {spec.source}", "",
             f"Settings changed: `{spec.settings}`; trials at E <= {spec.max_youngs_modulus_pa:g} Pa asking >= "
             f"{spec.min_grasp_force_n:g} N a finger, the most over the speed drive's ceiling first. "
             f"Re-run: **{len(pairs)} of {planned}**.",
             "", "Asked / ceiling: the force asked a finger over what the speed-driven hand pressed an FEM body "
                 "with at most (sim.hand.speed_drive_ceiling_n).", "",
             "| E (Pa) | asked / ceiling | re-run | negative -> positive | positive -> negative | "
             "positive before -> after |", "|---|---|---|---|---|---|"]
    # (modulus, asked / ceiling, stored label, new label) of each re-run trial
    rows = [(o["youngs_modulus_pa"], over_ceiling(o), _label(o), _label(n)) for o, n in pairs]
    for modulus in sorted({row[0] for row in rows}):
        for low, high in zip(CEILING_BANDS, CEILING_BANDS[1:]):
            band = [(a, b) for e, ratio, a, b in rows if e == modulus and low <= ratio < high]
            if band:
                lines.append(f"| {modulus:.0e} | {low:g}-{high:g} | {_change_cells(band)} |")
    lines.append(f"| all | | {_change_cells([(a, b) for _, _, a, b in rows])} |")
    return "\n".join(lines) + "\n" + _merged_signal(by_file, pairs)


def _change_cells(labels: list) -> str:
    """The report's cells of (stored, new) label pairs: re-run | negative -> positive | positive -> negative |
    positives before -> after."""
    return (f"{len(labels)} | {sum(a is False and b is True for a, b in labels)} | "
            f"{sum(a is True and b is False for a, b in labels)} | "
            f"{sum(a is True for a, _ in labels)} -> {sum(b is True for _, b in labels)}")


def _merged_signal(by_file: dict, pairs: list) -> str:
    """The signal report of the source with the re-run records in (what `defgg-datagen merge` would hold)."""
    if not pairs:
        return ""
    new = {n["trial_id"]: n for _, n in pairs}
    merged = [new.get(r["trial_id"], r) for records in by_file.values() for r in records]
    title = f"Signal report of the source with these {len(new)} records in (`defgg-datagen merge`, then `signal`)"
    return "\n" + render_markdown(signal_report(merged), title)


def merge(source: Path, relabelled: Path, out: Path) -> dict:
    """A whole dataset at `out`: `source`'s scenes, candidates and trials, each trial `relabelled` re-ran replaced
    by its new record; the header's trial settings are the relabel's and its "relabel" section says how many
    trials kept their source record (each record carries the settings it ran with). Written to a temporary
    folder and renamed: nothing half-written at `out`."""
    out = Path(out)
    if out.exists():
        raise DatasetError(f"{out} exists; merge writes a new dataset")
    relabel_header = json.loads((Path(relabelled) / HEADER_FILE).read_text(encoding="utf-8"))
    if relabel_header["source_fingerprint"] != dataset_fingerprint(source):
        raise DatasetError(f"{relabelled} relabelled another version of {source} (fingerprint differs)")
    new = {r["trial_id"]: r for r in relabelled_records(relabelled)}
    header = json.loads((Path(source) / "dataset.json").read_text(encoding="utf-8"))
    settings = TrialSettings.from_record(header["generator"]["trial_settings"])
    header["generator"]["trial_settings"] = settings.with_fields(**relabel_header["settings"]).to_record()
    tmp = out.with_name(out.name + ".partial")
    shutil.rmtree(tmp, ignore_errors=True)
    for folder in ("scenes", "candidates"):
        if (Path(source) / folder).is_dir():
            shutil.copytree(Path(source) / folder, tmp / folder)
    (tmp / "trials").mkdir(parents=True)
    counts = {"relabelled": 0, "kept": 0}
    for name, records in source_trials(source).items():
        merged = [new.get(r["trial_id"], r) for r in records]
        counts["relabelled"] += sum(r["trial_id"] in new for r in records)
        counts["kept"] += sum(r["trial_id"] not in new for r in records)
        write_text_atomic(tmp / "trials" / name, "".join(json.dumps(r, sort_keys=True) + "\n" for r in merged))
    header["relabel"] = {**relabel_header, "from": str(relabelled), **counts}
    write_json_atomic(tmp / "dataset.json", header)
    write_card(tmp)
    tmp.rename(out)
    return counts
