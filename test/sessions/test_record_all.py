"""sim_bringup/sessions/record_all.sh, the committed sessions' recipe, records a session that replays clean (it had
stopped working unnoticed once: the bring-up moved to a private domain the recorder could not see)."""
import os
import subprocess
from pathlib import Path

from support.replay_process import run_replay

ROOT = Path(__file__).resolve().parents[2]
SCRIPT = ROOT / "sim_bringup" / "sessions" / "record_all.sh"


def test_the_recipe_records_a_session_that_replays_clean(tmp_path):
    env = {**os.environ, "SESSIONS_OUT": str(tmp_path)}      # ROS_DOMAIN_ID: this pytest process's (conftest)
    done = subprocess.run(["bash", str(SCRIPT), "soft_objects"], capture_output=True, text=True, timeout=600,
                          env=env, cwd=ROOT)
    assert done.returncode == 0, done.stdout[-3000:] + done.stderr[-3000:]
    assert (tmp_path / "soft_objects" / "metadata.yaml").is_file()
    code, text = run_replay(tmp_path / "soft_objects", "--no-pick")
    assert code == 0, text[-3000:]


def test_an_unknown_session_is_refused():
    done = subprocess.run(["bash", str(SCRIPT), "no_such_session"], capture_output=True, text=True, timeout=60,
                          cwd=ROOT)
    assert done.returncode == 2 and "unknown session no_such_session" in done.stderr
