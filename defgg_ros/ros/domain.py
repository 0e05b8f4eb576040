"""Private ROS domain ids for graphs that must not see the caller's (replays, tests, benchmarks).

Ids 0..101 only: Fast DDS maps domain d to UDP ports 7400 + 250 * d (+ offsets), and above 101
those land in Linux's ephemeral port range (32768..60999), where any other socket may already hold
them; CI lost whole replayed frames in domains 101-230. ROS 2's own docs give the same safe range.
"""
import os
import random

SAFE_DOMAIN_RANGE = (0, 101)


def pick_private_domain(exclude=(), rng=random) -> int:
    """A random safe domain id other than 0, this process's ROS_DOMAIN_ID and the ids in `exclude`.

    Never 0: it is ROS 2's default, where a lab's real arm controller usually listens."""
    taken = {str(d) for d in exclude} | {os.environ.get("ROS_DOMAIN_ID", "0"), "0"}
    choices = [d for d in range(SAFE_DOMAIN_RANGE[0], SAFE_DOMAIN_RANGE[1] + 1) if str(d) not in taken]
    return rng.choice(choices)


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
                f"(--ros-domain inherit); other machines on the network may see this graph")
    if choice == PRIVATE:
        caller_id = env.get("ROS_DOMAIN_ID", "0") or "0"
        domain = rng.choice([d for d in range(max(1, SAFE_DOMAIN_RANGE[0]), SAFE_DOMAIN_RANGE[1] + 1)
                             if str(d) != caller_id])
        how = "private, picked at random"
    else:
        domain, how = int(choice), "chosen with --ros-domain"
    env["ROS_DOMAIN_ID"] = str(domain)
    env["ROS_AUTOMATIC_DISCOVERY_RANGE"] = LOCALHOST_RANGE
    return (f"ROS domain {domain} ({how}), discovery localhost only; to join it: "
            f"export ROS_DOMAIN_ID={domain} ROS_AUTOMATIC_DISCOVERY_RANGE={LOCALHOST_RANGE}; "
            f"--ros-domain inherit uses this shell's domain ({callers}) instead")
