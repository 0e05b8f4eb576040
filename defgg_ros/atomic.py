"""Write files so that a crash never leaves a half-written one behind."""
import fcntl
import gzip
import json
import os
import tempfile
from contextlib import contextmanager
from pathlib import Path

# A secret file (credentials, tokens) stays readable by its owner only.
SECRET_MODE = 0o600


def default_file_mode() -> int:
    """The mode open() gives a new file here: 0o666 minus the process umask (0o644 with umask 022).

    Read from /proc (Linux) so the umask is never changed, not even for an instant; elsewhere the
    classic set-and-restore.
    """
    try:
        with open("/proc/self/status", encoding="ascii") as status:
            for line in status:
                if line.startswith("Umask:"):
                    return 0o666 & ~int(line.split()[1], 8)
    except (OSError, ValueError):
        pass
    umask = os.umask(0o022)
    os.umask(umask)
    return 0o666 & ~umask


@contextmanager
def atomic_path(path, secret: bool = False):
    """Yield a temporary path beside `path`; rename it over `path` on success.

    The temporary file is removed when the body raises, so readers only ever
    see the old file or the complete new one. The file gets the mode of any
    other new file (mkstemp alone would leave 0600: run.json, summary.json and
    checkpoints were private while their neighbours were 0644), or SECRET_MODE
    when `secret`. The mode is set before the rename, so the file never appears
    at `path` with another.
    """
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    fd, tmp = tempfile.mkstemp(prefix=f".{path.name}.", suffix=".tmp", dir=path.parent)
    os.close(fd)
    try:
        yield Path(tmp)
        with open(tmp, "rb") as f:
            os.fsync(f.fileno())
        os.chmod(tmp, SECRET_MODE if secret else default_file_mode())
        os.replace(tmp, path)
    except BaseException:
        if os.path.exists(tmp):
            os.unlink(tmp)
        raise


def write_text_atomic(path, text: str, secret: bool = False) -> None:
    with atomic_path(path, secret=secret) as tmp:
        Path(tmp).write_text(text, encoding="utf-8")


def write_json_atomic(path, obj, secret: bool = False) -> None:
    write_text_atomic(path, json.dumps(obj, indent=2, sort_keys=True) + "\n", secret=secret)


def append_jsonl(path, record: dict) -> None:
    """Append one JSON record as a line and fsync it (one writer per file).

    A crash can leave at most a truncated last line, which read_jsonl skips and the next append truncates first:
    appended to, it would glue the next record on and leave a corrupt line in the middle of the file.
    """
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    line = json.dumps(record, sort_keys=True, allow_nan=False) + "\n"
    repair_torn_tail(path)
    with open(path, "a", encoding="utf-8") as f:
        f.write(line)
        f.flush()
        os.fsync(f.fileno())


def repair_torn_tail(path) -> int:
    """Drop an incomplete last line (no trailing newline). Returns the bytes removed."""
    path = Path(path)
    if not path.exists() or path.stat().st_size == 0:
        return 0
    with open(path, "rb+") as f:
        f.seek(0, os.SEEK_END)
        size = f.tell()
        f.seek(size - 1)
        if f.read(1) == b"\n":
            return 0
        # Walk back to the last newline; everything after it is the torn record.
        pos = size - 1
        chunk = 4096
        while pos > 0:
            start = max(0, pos - chunk)
            f.seek(start)
            data = f.read(pos - start)
            idx = data.rfind(b"\n")
            if idx >= 0:
                keep = start + idx + 1
                break
            pos = start
        else:
            keep = 0
        f.truncate(keep)
        f.flush()
        os.fsync(f.fileno())
        return size - keep


def read_jsonl(path) -> list:
    """Read the complete records of a JSON-lines file, plain or gzip-compressed (*.gz); skip a torn last line."""
    path = Path(path)
    if not path.exists():
        return []
    records = []
    with (gzip.open(path, "rt", encoding="utf-8") if path.suffix == ".gz" else open(path, encoding="utf-8")) as f:
        lines = f.read().split("\n")
    for i, line in enumerate(lines):
        if not line.strip():
            continue
        try:
            records.append(json.loads(line))
        except json.JSONDecodeError:
            # A crash mid-write leaves the last line without its newline (append_jsonl writes the line and its
            # newline in one write): skipped. A complete line that does not parse is corruption, wherever it is.
            if i == len(lines) - 1:
                continue
            raise ValueError(f"{path}: corrupt record on line {i + 1}") from None
    return records


def compress_jsonl(path) -> Path:
    """Replace a finished JSON-lines file by <path>.gz (the same records; written atomically, then the
    original removed). Returns the new path."""
    path = Path(path)
    out = path.with_name(path.name + ".gz")
    data = path.read_bytes()
    with atomic_path(out) as tmp, open(tmp, "wb") as raw, gzip.GzipFile(fileobj=raw, mode="wb", mtime=0) as gz:
        gz.write(data)
    path.unlink()
    return out


@contextmanager
def only_writer(lock_path, busy_error: Exception):
    """Hold an exclusive lock on lock_path while a run writes a folder; raise busy_error when another process holds
    it (two runs appending to the same files would write each trial twice)."""
    with open(lock_path, "w") as lock:
        try:
            fcntl.flock(lock, fcntl.LOCK_EX | fcntl.LOCK_NB)
        except BlockingIOError:
            raise busy_error from None
        yield
