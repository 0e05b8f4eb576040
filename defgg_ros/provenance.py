"""What a result ran on: the code's commit and a file's hash (light: no torch, no rclpy)."""
import hashlib
import subprocess


def git_commit(repo_dir=".") -> str:
    """HEAD of the checkout at repo_dir, marked when defgg_ros/ has uncommitted changes; 'unknown' outside git."""
    try:
        out = subprocess.run(["git", "rev-parse", "HEAD"], cwd=repo_dir, capture_output=True, text=True, check=True)
        dirty = subprocess.run(["git", "status", "--porcelain", "--untracked-files=no", "defgg_ros"], cwd=repo_dir,
                               capture_output=True, text=True, check=True).stdout.strip()
    except (OSError, subprocess.CalledProcessError):
        return "unknown"
    return out.stdout.strip() + (" (+ uncommitted changes in defgg_ros/)" if dirty else "")


def file_sha256(path) -> str:
    """The file's SHA-256 (hex), read in 1 MiB blocks."""
    h = hashlib.sha256()
    with open(path, "rb") as f:
        for block in iter(lambda: f.read(1 << 20), b""):
            h.update(block)
    return h.hexdigest()
