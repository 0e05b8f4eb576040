"""Private ROS domain ids for graphs that must not see the caller's (replays, tests, benchmarks).

Ids 0..101 only: Fast DDS maps domain d to UDP ports 7400 + 250 * d (+ offsets), and above 101
those land in Linux's ephemeral port range (32768..60999), where any other socket may already hold
them; CI lost whole replayed frames in domains 101-230. ROS 2's own docs give the same safe range.

Private means nobody else uses it: the cells, demos, replays and benches draw from PRIVATE_DOMAIN_RANGE and
the test processes from TEST_DOMAIN_RANGE (disjoint, so a test never joins a running demo), and a drawn id is
taken only when its host-wide lock file can be locked (`claim_domain`: flock on
<tmp>/defgg-ros-domain-<id>.lock, held until the process exits; a crashed holder's lock goes with it).
"""
import fcntl
import os
import random
import tempfile
from pathlib import Path

SAFE_DOMAIN_RANGE = (0, 101)
PRIVATE_DOMAIN_RANGE = (1, 50)     # bringup, demo, replays, benches (never 0: ROS 2's default, a real cell's)
TEST_DOMAIN_RANGE = (51, 101)      # one per pytest process (test/conftest.py)
LOCK_DIR_VARIABLE = "DEFGG_DOMAIN_LOCK_DIR"   # where the lock files live (default: the system's temp folder)

_held_locks: dict = {}   # domain id -> open lock file, kept for the life of the process


class DomainInUse(RuntimeError):
    """No domain of the range could be claimed."""


def lock_path(domain_id: int) -> Path:
    folder = os.environ.get(LOCK_DIR_VARIABLE) or tempfile.gettempdir()
    return Path(folder) / f"defgg-ros-domain-{int(domain_id)}.lock"


def claim_domain(domain_id: int) -> bool:
    """Lock domain_id for this process host-wide (True), or False when another process holds it (or its lock
    file cannot be opened, e.g. another user's). Claiming a domain this process already holds is True."""
    domain_id = int(domain_id)
    if domain_id in _held_locks:
        return True
    try:
        fd = os.open(lock_path(domain_id), os.O_RDWR | os.O_CREAT, 0o666)
    except OSError:
        return False
    try:
        fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
    except OSError:
        os.close(fd)
        return False
    os.write(fd, f"{os.getpid()}\n".encode())
    _held_locks[domain_id] = fd
    return True


def domain_claimed_elsewhere(domain_id: int) -> bool:
    """Does another process hold domain_id's lock right now? (This process's own claim is not 'elsewhere'.)"""
    if int(domain_id) in _held_locks:
        return False
    if not claim_domain(domain_id):
        return True
    release_domain(domain_id)
    return False


def release_domain(domain_id: int) -> None:
    fd = _held_locks.pop(int(domain_id), None)
    if fd is not None:
        os.close(fd)   # closing the file drops the flock


def pick_private_domain(exclude=(), rng=random, domain_range=PRIVATE_DOMAIN_RANGE) -> int:
    """A domain id of domain_range (default PRIVATE_DOMAIN_RANGE) other than 0, this process's ROS_DOMAIN_ID and
    the ids in `exclude`, claimed for this process (claim_domain): in random order, the first nobody holds (this
    process included).
    DomainInUse when every candidate is held."""
    low, high = domain_range
    if not SAFE_DOMAIN_RANGE[0] <= low <= high <= SAFE_DOMAIN_RANGE[1]:
        raise ValueError(f"domain range {domain_range} is outside {SAFE_DOMAIN_RANGE}")
    taken = {str(d) for d in exclude} | {os.environ.get("ROS_DOMAIN_ID", "0"), "0"}
    choices = [d for d in range(low, high + 1) if str(d) not in taken]
    rng.shuffle(choices)
    for domain_id in choices:
        if domain_id not in _held_locks and claim_domain(domain_id):   # one already held here is in use too
            return domain_id
    raise DomainInUse(f"every ROS domain in {low}..{high} is in use on this host (lock files {lock_path(low)} ...)")


# --- isolation of the cell's own graph (`make demo`, `defgg-bringup` sim sets) -------------------
# A lab's real arm controller usually listens in domain 0 with default (subnet-wide) discovery; a
# simulated cell started there would publish trajectories it could receive. The sim entry points
# therefore run, unless told otherwise, in a private domain with discovery limited to this host.
ISOLATION_ENV = "DEFGG_ROS_DOMAIN"    # default of --ros-domain (e.g. `make demo DEFGG_ROS_DOMAIN=inherit`)
PRIVATE, INHERIT = "private", "inherit"
LOCALHOST_RANGE = "LOCALHOST"         # ROS 2 Jazzy's ROS_AUTOMATIC_DISCOVERY_RANGE value for "this host only"


def parse_domain_choice(text: str) -> str | int:
    """'private' | 'inherit' | a domain id in SAFE_DOMAIN_RANGE (ValueError with the accepted forms)."""
    choice = str(text).strip().lower()
    if choice in (PRIVATE, INHERIT):
        return choice
    try:
        domain = int(choice)
    except ValueError:
        raise ValueError(f"ROS domain {text!r}: expected 'private', 'inherit' or a domain id "
                         f"{SAFE_DOMAIN_RANGE[0]}..{SAFE_DOMAIN_RANGE[1]}") from None
    if not SAFE_DOMAIN_RANGE[0] <= domain <= SAFE_DOMAIN_RANGE[1]:
        raise ValueError(f"ROS domain {domain} is outside {SAFE_DOMAIN_RANGE[0]}..{SAFE_DOMAIN_RANGE[1]} "
                         "(higher ids map to ports in Linux's ephemeral range)")
    return domain


def default_domain_choice(env=None) -> str:
    """The --ros-domain default: $DEFGG_ROS_DOMAIN, else 'private'."""
    env = os.environ if env is None else env
    return env.get(ISOLATION_ENV, PRIVATE) or PRIVATE


def apply_domain_choice(choice, env=None, rng=random) -> str:
    """Set ROS_DOMAIN_ID / ROS_AUTOMATIC_DISCOVERY_RANGE in `env` (default os.environ) for `choice`.

    Call before rclpy.init and before starting child processes (they inherit `env`).
    'private': a random id in SAFE_DOMAIN_RANGE other than 0 and the caller's, localhost-only
    discovery; an int: that id, localhost-only discovery; 'inherit': leave both as they are.
    Returns one line for the log that says which domain and discovery the graph uses.
    """
    env = os.environ if env is None else env
    choice = parse_domain_choice(choice) if isinstance(choice, str) else choice
    callers = env.get("ROS_DOMAIN_ID", "") or "0 (unset)"
    if choice == INHERIT:
        discovery = env.get("ROS_AUTOMATIC_DISCOVERY_RANGE", "") or "SUBNET (default)"
        return (f"ROS domain {callers}, discovery {discovery}: inherited from the environment "
                f"(--ros-domain inherit); {_who_may_see(env)}")
    if choice == PRIVATE:
        caller_id = env.get("ROS_DOMAIN_ID", "0") or "0"
        domain = pick_private_domain(exclude=(caller_id,), rng=rng)
        how = "private: picked at random among the ids no other process on this host holds"
    else:
        domain, how = int(choice), "chosen with --ros-domain"
        if not claim_domain(domain):
            how += f"; WARNING: another process on this host holds it ({lock_path(domain)})"
    env["ROS_DOMAIN_ID"] = str(domain)
    env["ROS_AUTOMATIC_DISCOVERY_RANGE"] = LOCALHOST_RANGE
    return (f"ROS domain {domain} ({how}), discovery localhost only; to join it: "
            f"export ROS_DOMAIN_ID={domain} ROS_AUTOMATIC_DISCOVERY_RANGE={LOCALHOST_RANGE}; "
            f"--ros-domain inherit uses this shell's domain ({callers}) instead")


def _who_may_see(env) -> str:
    """Who can see an inherited graph: ROS 2 Jazzy reads ROS_AUTOMATIC_DISCOVERY_RANGE (LOCALHOST, OFF, SUBNET,
    SYSTEM_DEFAULT; unset = SUBNET) and still honours the deprecated ROS_LOCALHOST_ONLY=1 as LOCALHOST."""
    discovery = (env.get("ROS_AUTOMATIC_DISCOVERY_RANGE", "") or "").strip().upper()
    if discovery == "OFF":
        return "discovery is off: only this process's own nodes see each other"
    if discovery == LOCALHOST_RANGE or (not discovery and env.get("ROS_LOCALHOST_ONLY", "") == "1"):
        return "only this machine's processes on that domain see this graph"
    return "other machines on the network may see this graph"
