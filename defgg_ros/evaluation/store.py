"""The results file of an evaluation: one JSON line per finished trial.

Why JSON lines: each finished trial is one fsync'd append
(``defgg_ros.atomic.append_jsonl``), so a SIGKILL loses at most the trials in
flight. A kill during the append can leave a torn last line; ``append_jsonl``
truncates it before appending again (otherwise the next record would be glued
to it and the file would become unreadable). Only the parent process writes,
and it skips keys that are already present, so a rerun duplicates nothing.
"""
from __future__ import annotations

from pathlib import Path

from defgg_ros.atomic import append_jsonl, read_jsonl, repair_torn_tail

RESULTS_FILE = "trials.jsonl"
RECORD_VERSION = 1


class ResultsError(RuntimeError):
    """A results file that cannot be trusted (corrupt line, duplicate key, wrong version)."""


def results_path(out_dir) -> Path:
    """An evaluation folder's results file: trials.jsonl, or trials.jsonl.gz once sealed (compressed,
    complete: read the same way, never appended to)."""
    plain = Path(out_dir) / RESULTS_FILE
    sealed = plain.with_name(plain.name + ".gz")
    return sealed if sealed.exists() and not plain.exists() else plain


class ResultStore:
    """Append-only trial records keyed by ``record["key"]``."""

    def __init__(self, out_dir):
        self.out_dir = Path(out_dir)
        self.path = results_path(self.out_dir)
        self.out_dir.mkdir(parents=True, exist_ok=True)
        self.sealed = self.path.suffix == ".gz"
        self.torn_bytes_removed = 0 if self.sealed else repair_torn_tail(self.path)
        self._records = {}
        for i, rec in enumerate(read_results(self.path)):
            self._records[rec["key"]] = rec
            if len(self._records) != i + 1:
                raise ResultsError(f"{self.path}: duplicate trial key {rec['key']!r}")

    def __contains__(self, key: str) -> bool:
        return key in self._records

    def __len__(self) -> int:
        return len(self._records)

    def get(self, key: str) -> dict | None:
        return self._records.get(key)

    def records(self) -> list:
        return list(self._records.values())

    def by_sim_key(self) -> dict:
        """sim_key -> first record that really ran that simulation (for reuse)."""
        out = {}
        for rec in self._records.values():
            if rec.get("reused_from") is None and rec.get("sim_key"):
                out.setdefault(rec["sim_key"], rec)
        return out

    def append(self, record: dict) -> bool:
        """Append a finished trial; False (and nothing written) if its key is already stored."""
        key = record.get("key")
        if not key:
            raise ResultsError("a trial record needs a non-empty 'key'")
        if self.sealed:
            raise ResultsError(f"{self.path}: the folder's results are sealed (compressed, complete); "
                               "evaluate into a new --out folder")
        if key in self._records:
            return False
        record = {**record, "record_version": RECORD_VERSION}
        append_jsonl(self.path, record)
        self._records[key] = record
        return True


def read_results(path) -> list:
    """All complete records of a results file (a torn last line is skipped)."""
    try:
        records = read_jsonl(path)
    except ValueError as exc:
        raise ResultsError(str(exc)) from None
    for i, rec in enumerate(records):
        if not isinstance(rec, dict) or "key" not in rec:
            raise ResultsError(f"{path}: record {i + 1} has no 'key'")
        if rec.get("record_version", RECORD_VERSION) != RECORD_VERSION:
            raise ResultsError(f"{path}: record {i + 1} has version {rec.get('record_version')}, "
                               f"this code reads {RECORD_VERSION}")
    return records
