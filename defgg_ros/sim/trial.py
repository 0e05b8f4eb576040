"""One grasp trial: close, lift, shake test (16 directions) and twist test.

The hand closes with the force the trial protocol gives (sim.protocol.TrialProtocol: grip force rule,
gravity, pickup, finger hold, loss rule, material, label rule), picks the object up, then for each direction
the acceleration is ramped until the object is no longer held or the limit is reached; the held value is
recorded per direction. Positive when the mean is >= SHAKE_POSITIVE_THRESHOLD_MPS2 (TrialRecord.label).

The shake uses the gravity trick measured in the FEM notes: the hand stays
still and gravity is set to g - a*d, which matched moving the hand within
0.1 m/s^2. The twist really rotates the hand (a non-uniform field cannot be
faked by gravity), one way or oscillating (TrialMotion.twist_oscillation_radps).
The grasp+lift state is shared by all directions:
saveState does not cover soft nodes, so LoadedObject.restore_state resets
the nodes with resetMeshData and zeroes their velocities.

Speed-ups (validated against TrialSettings.naive() in bench/bench_datagen.py).
Exact (the defaults, TrialSettings.exact()): stop a direction as soon as the
object is lost; stop the remaining directions once the label is decided (mean
can no longer reach, or can no longer miss, the threshold); skipped directions
are stored as the bound that decided the label (50 / 0). Surrogate (on in
TrialSettings.fast(), the generator's): after >= 3 directions stop when the
measured mean is far from the threshold; skipped directions hold the measured
mean. Skipped directions are flagged False in `shake_measured`. The evaluation's
exact stop (shake_stop_when_decided) also ends a direction's ramp once held at
the value that decides both its outcomes (shake_outcome_cap).
"""
from __future__ import annotations

import math
import time
from dataclasses import dataclass, field, replace

import numpy as np
import pybullet as p

from defgg_ros.constants import (
    GRIPPER_MAX_WIDTH_M,
    HELD_LIMIT_TOLERANCE,
    SHAKE_ACCEL_LIMIT_MPS2,
    SHAKE_DIRECTIONS,
    SHAKE_POSITIVE_THRESHOLD_MPS2,
    STATUS_EXPLODED,
    STATUS_LIFT_FAILED,
    STATUS_OK,
    STATUS_TIMEOUT,
    TWIST_ACCEL_LIMIT_RADPS2,
    TWIST_POSITIVE_THRESHOLD_RADPS2,
)
from defgg_ros.sim import hand as hand_mod
from defgg_ros.sim import objects, world
from defgg_ros.sim.hand import world_T_hand
from defgg_ros.sim.trial_settings import TrialSettings  # noqa: F401 - run_grasp_trial's settings

# The protocol (gravity, grip force, finger hold, loss rule, material, label rule) is one value,
# sim.protocol.TrialProtocol; the trial asks it (docs/dataset.md, "Trial protocols").
TABLE_AWAY_Z_M = -1.0   # where the table_away pickup moves the table (DefGraspSim lowers its platform)

OPENING_CLEARANCE_M = 0.01      # fingers open this much wider than the grasp width (5 mm a side)
# Energy blow-up: kinetic energy per kg = v_rms^2 / 2. The fastest real motion in a trial is the
# twist at its limit (500 rad/s^2 ramped over 0.5 s: 125 rad/s, ~6 m/s at 5 cm); 30 m/s RMS over
# all nodes (450 J/kg) is far beyond it and only reached by a diverging FEM solve.
MAX_RMS_NODE_SPEED_MPS = 30.0
TWIST_AXES = ((1, 0, 0), (-1, 0, 0), (0, 1, 0), (0, -1, 0), (0, 0, 1), (0, 0, -1))


def shake_directions(n: int = SHAKE_DIRECTIONS) -> np.ndarray:
    """n unit vectors spread over the sphere (Fibonacci lattice), in an order that
    interleaves them so any prefix covers the sphere evenly (early stops stay fair)."""
    i = np.arange(n) + 0.5
    z = 1 - 2 * i / n
    phi = math.pi * (1 + 5**0.5) * i
    dirs = np.c_[np.sqrt(1 - z * z) * np.cos(phi), np.sqrt(1 - z * z) * np.sin(phi), z]
    bits = max(1, (n - 1).bit_length())
    order = [k for k in (int(f"{i:0{bits}b}"[::-1], 2) for i in range(2**bits)) if k < n]  # bit reversal
    return dirs[order]


@dataclass(frozen=True)
class WorldGrasp:
    """Top-down grasp in the world frame: TCP position (m), yaw of the closing direction, width (m), and the
    opening the fingers start from (m): None = width + OPENING_CLEARANCE_M (every grasp before sampler 4);
    the sampler sets a wider one where the object widens under the fingers (sim.sampler.swept_opening_m)."""
    position_m: tuple
    yaw_rad: float
    width_m: float
    opening_m: float | None = None

    def __post_init__(self):
        if not np.all(np.isfinite(self.position_m)) or len(self.position_m) != 3:
            raise ValueError(f"grasp position must be 3 finite numbers, got {self.position_m}")
        if not 0.0 < self.width_m <= GRIPPER_MAX_WIDTH_M:
            raise ValueError(f"grasp width {self.width_m} m outside (0, {GRIPPER_MAX_WIDTH_M}]")
        if self.opening_m is not None and not self.width_m <= self.opening_m <= GRIPPER_MAX_WIDTH_M:
            raise ValueError(f"grasp opening {self.opening_m} m outside [width {self.width_m}, {GRIPPER_MAX_WIDTH_M}]")

    def finger_opening_m(self) -> float:
        """The opening the fingers start closing from."""
        if self.opening_m is not None:
            return self.opening_m
        return min(self.width_m + OPENING_CLEARANCE_M, GRIPPER_MAX_WIDTH_M)


@dataclass
class TrialOutcome:
    status: str
    shake_accels_mps2: list | None = None
    shake_measured: list | None = None
    twist_accels_radps2: list | None = None
    twist_measured: list | None = None
    grasp_force_n: float = 0.0
    cpu_s: float = 0.0
    sim_steps: int = 0
    note: str = ""
    sim: dict = field(default_factory=dict)

    @property
    def shake_mean_mps2(self) -> float | None:
        return None if not self.shake_accels_mps2 else float(np.mean(self.shake_accels_mps2))


class _Abort(Exception):
    def __init__(self, status, note):
        super().__init__(note)
        self.status, self.note = status, note


class _Trial:
    def __init__(self, client, spec, grasp, settings: TrialSettings, object_xy_m, object_yaw_rad):
        self.client, self.grasp, self.settings = client, grasp, settings
        self.protocol, self.motion = settings.protocol, settings.motion
        self.stops, self.evaluation = settings.generator, settings.evaluation
        self.material = self.protocol.material
        if self.material.poisson_ratio is not None:
            spec = replace(spec, poisson_ratio=self.material.poisson_ratio)
        self.spec = spec
        self.world = world.create_world(client, spec.part_moduli_pa(), self.motion.time_step_s)
        self.obj = objects.load_object(client, spec, object_xy_m, object_yaw_rad,
                                       friction=self.material.object_friction)
        self.force_n = self.protocol.finger_force_n(min(spec.part_moduli_pa()), self.obj.mass_kg)
        self.gravity = self.protocol.test_gravity_mps2()   # during the squeeze, the pickup and the tests
        self.fingers_locked = False
        self.steps = 0
        self.last_points = None   # for the energy check; None after a restore (a deliberate jump)
        self.t0 = time.process_time()
        self.check_steps = max(1, round(self.motion.check_every_s / self.world.time_step_s))

    def step(self, n):
        """n physics steps, checked for blow-ups and the CPU budget every check_steps."""
        while n > 0:
            k = min(n, self.check_steps)
            for _ in range(k):
                self.world.step()
            self._check(k)
            n -= k

    def _check(self, n):
        self.steps += n
        points = self.obj.tracked_points()
        if not self.obj.is_finite(points=points):
            raise _Abort(STATUS_EXPLODED, "object nodes non-finite or runaway")
        speed = rms_speed_mps(self.last_points, points, n * self.world.time_step_s)
        if speed > MAX_RMS_NODE_SPEED_MPS:
            raise _Abort(STATUS_EXPLODED, f"energy blow-up: RMS node speed {speed:.0f} m/s "
                                          f"(limit {MAX_RMS_NODE_SPEED_MPS:.0f} m/s)")
        self.last_points = points
        if time.process_time() - self.t0 > self.motion.max_cpu_s:
            raise _Abort(STATUS_TIMEOUT, f"trial exceeded {self.motion.max_cpu_s} s CPU")

    def seconds(self, t_s):
        return max(1, round(t_s / self.world.time_step_s))

    def grasp_and_lift(self):
        m = self.motion
        self.step(self.seconds(m.settle_before_s))      # settles under gravity on the table
        self.world.set_gravity(self.gravity)             # zero from here on when the protocol says so
        opening = self.grasp.finger_opening_m()
        self.tcp = world_T_hand(self.grasp.position_m, self.grasp.yaw_rad)
        self.hand = hand_mod.create_hand(self.client, self.tcp, opening, friction=self.material.finger_friction)
        press = self.protocol.finger_drive == "press"
        self.hand.close(self.force_n, m.close_speed_mps, press=press)
        if press:                  # the speed drive needs nothing per step: no call on its hot path
            self.world.before_step = self.hand.drive
        self.step(self.seconds(opening / 2 / m.close_speed_mps + m.close_settle_s))
        if self.hand.finger_opening_m() < 1e-3:
            raise _Abort(STATUS_LIFT_FAILED, "fingers closed on nothing")
        if self.protocol.pickup == "table_away":
            self._pickup_without_gravity()
        else:
            self._lift()
        self.ref_offset = self.object_in_hand()
        if not self.held():
            raise _Abort(STATUS_LIFT_FAILED, "object not held after lift")
        self.hold_fingers_for_tests()
        self.squeeze_after_pickup_n = self.hand.finger_forces_n()
        self.saved = (self.obj.save_state(), self.hand.save_state())

    def hold_fingers_for_tests(self):
        """Lock the fingers when the protocol says so (TrialProtocol.locks_fingers); else they keep pushing."""
        if self.protocol.locks_fingers(all(pt.soft for pt in self.obj.parts)):
            self.hand.lock_fingers()
            self.fingers_locked = True
            self.step(self.check_steps)

    def _lift(self):
        """lift pickup: lift the object off the table with a smooth profile, then hold."""
        s = self.motion
        n_lift = self.seconds(s.lift_time_s)
        for k in range(0, n_lift, self.check_steps):
            frac = min(1.0, (k + self.check_steps) / n_lift)
            target = self.tcp.copy()
            target[2, 3] += s.lift_height_m * 0.5 * (1 - math.cos(math.pi * frac))
            self.hand.move_to(target)
            self.step(self.check_steps)
        self.step(self.seconds(s.hold_time_s))
        self.lifted_tcp = target

    def _pickup_without_gravity(self):
        """table_away pickup: the squeeze has settled; move the table away and hold (the hand stays put)."""
        self.world.move_table(TABLE_AWAY_Z_M)
        self.step(self.seconds(self.motion.hold_time_s))
        self.lifted_tcp = self.tcp.copy()

    def protocol_facts(self) -> dict:
        """What the trial really did, read back from the engine after the pickup (recorded per trial)."""
        return {"gravity_during_test_mps2": self.world.gravity(), "finger_force_set_n": self.force_n,
                "fingers_locked": self.fingers_locked,
                "squeeze_after_pickup_n": [round(f, 6) for f in self.squeeze_after_pickup_n],
                "loss_rule": self.protocol.loss_rule}

    def held(self) -> bool:
        contacts = np.sum([self.hand.finger_contacts(b) for b in self.obj.body_ids], axis=0)
        return self.protocol.held(contacts, lambda: float(np.linalg.norm(self.object_in_hand() - self.ref_offset)))

    def object_in_hand(self) -> np.ndarray:
        """Object centroid in the hand frame (so the twist's rotation is not mistaken for a loss)."""
        pose = self.hand.pose()
        return pose[:3, :3].T @ (self.obj.centroid_m() - pose[:3, 3])

    def restore(self):
        self.last_points = None
        self.obj.restore_state(self.saved[0])
        self.hand.restore_state(self.saved[1])
        self.hand.move_to(self.lifted_tcp)
        self.world.set_gravity(self.gravity)

    def ramp(self, limit, ramp_time_s, apply, stop_at=None) -> float:
        """Ramp 0..limit over ramp_time_s calling apply(value); return the last held value. stop_at: end the
        ramp once held at that value (the full ramp would return at least the value reached)."""
        n = self.seconds(ramp_time_s)
        held_value, lost = limit, False
        for k in range(0, n, self.check_steps):
            value = limit * min(1.0, (k + self.check_steps) / n)
            apply(value, self.check_steps)
            if not lost and not self.held():
                lost, held_value = True, max(0.0, value - limit * self.check_steps / n)
                if self.stops.stop_direction_when_lost:
                    break
            if not lost and stop_at is not None and value >= stop_at:
                return value
        return held_value

    def shake(self):
        g = self.gravity
        dirs = shake_directions(self.motion.shake_directions)
        values, measured = [], []
        for d in dirs:
            self.restore()

            def apply(a, n, d=d):
                self.world.set_gravity(g - a * d)
                self.step(n)

            cap = self._shake_outcome_cap(values, len(dirs))
            values.append(self.ramp(self.evaluation.shake_limit_mps2, self.motion.shake_ramp_time_s, apply, cap))
            measured.append(cap is None or values[-1] < cap)    # a capped direction holds a lower bound
            left = len(dirs) - len(values)
            if self.stops.confident_stop and left and _confidently_decided(
                    values, self.stops.confident_min_directions, self.stops.confident_margin_mps2):
                values += [float(np.mean(values))] * left    # imputed by the measured mean
                measured += [False] * left
                break
            fail_below = self.evaluation.shake_fail_below_mps2
            if fail_below is not None and values[-1] < fail_below and left:
                values += [0.0] * left
                measured += [False] * left
                break
            fill = label_decided_fill(values, len(dirs), SHAKE_POSITIVE_THRESHOLD_MPS2, SHAKE_ACCEL_LIMIT_MPS2) \
                if self.stops.stop_when_label_decided or self._both_outcomes_may_stop(values) else None
            if fill is not None:
                values += [fill] * left
                measured += [False] * left
                break
        self.world.set_gravity(g)
        return values, measured

    def _shake_outcome_cap(self, values, total: int) -> float | None:
        if not self.evaluation.shake_stop_when_decided:
            return None
        return shake_outcome_cap(values, total, self.evaluation.shake_limit_mps2)

    def _both_outcomes_may_stop(self, values) -> bool:
        """shake_stop_when_decided: the every-direction outcome is certain (a measured direction was not held
        at the threshold), so the shake may stop as soon as the mean's is too."""
        every_failed = min(values) < SHAKE_POSITIVE_THRESHOLD_MPS2 * (1 - HELD_LIMIT_TOLERANCE)
        return self.evaluation.shake_stop_when_decided and every_failed

    def twist(self):
        values, fill = [], 0.0     # axes skipped after a failure hold 0
        osc = self.motion.twist_oscillation_radps
        for axis in TWIST_AXES:
            self.restore()
            state = {"omega": 0.0, "theta": 0.0, "t": 0.0}
            axis_w = self.lifted_tcp[:3, :3] @ np.asarray(axis, dtype=float)

            def apply(level, n, axis_w=axis_w, state=state):
                if osc is None:    # one way for the whole ramp: the hand spins up to 125 rad/s
                    self._turn(axis_w, state, level, n * self.world.time_step_s)
                    self.world.step(n)
                else:              # level * sin(osc * t): the spin stays below level / osc
                    dt = self.world.time_step_s
                    for _ in range(n):
                        state["t"] += dt
                        self._turn(axis_w, state, level * math.sin(osc * state["t"]), dt)
                        self.world.step()
                self._check(n)

            values.append(self.ramp(TWIST_ACCEL_LIMIT_RADPS2, self.motion.twist_ramp_time_s, apply))
            fail_below = self.evaluation.twist_fail_below_radps2
            if fail_below is not None and values[-1] < fail_below:
                break
            decided = label_decided_fill(values, len(TWIST_AXES), TWIST_POSITIVE_THRESHOLD_RADPS2,
                                         TWIST_ACCEL_LIMIT_RADPS2) if self.stops.stop_when_label_decided else None
            if decided is not None:
                fill = decided
                break
        # Skipped axes hold `fill`, flagged in twist_measured.
        left = len(TWIST_AXES) - len(values)
        return values + [fill] * left, [True] * len(values) + [False] * left

    def _turn(self, axis_w, state, alpha_radps2, dt_s):
        """Integrate the hand's angular acceleration about axis_w over dt_s and move the palm's target."""
        state["omega"] += alpha_radps2 * dt_s
        state["theta"] += state["omega"] * dt_s
        target = self.lifted_tcp.copy()
        target[:3, :3] = _axis_angle(axis_w, state["theta"]) @ self.lifted_tcp[:3, :3]
        self.hand.move_to(target)


def label_decided_fill(values, total: int, threshold: float, limit: float) -> float | None:
    """The generator's exact stop (stop_when_label_decided; the evaluation measures everything), shared by
    the shake's directions and the twist's axes: once the mean over `total` tests is certain to reach
    `threshold` (held values are >= 0) or to miss it (each holds at most `limit`), the value that fills the
    remaining tests without changing that (0, or the limit); else None."""
    left = total - len(values)
    if not left:
        return None
    need = threshold * total
    if sum(values) >= need:
        return 0.0
    if sum(values) + limit * left < need:
        return limit
    return None


def shake_outcome_cap(values, total: int, limit: float) -> float | None:
    """shake_stop_when_decided: the held acceleration beyond which the next direction changes neither of the
    evaluation's outcomes, None when any value up to `limit` can. The mean is certain once the held sum reaches
    threshold * total (held values are >= 0); "held in every direction" needs the threshold until a direction
    has failed. Exact: the full ramp would hold at least the value the capped one reached."""
    mean_needs = SHAKE_POSITIVE_THRESHOLD_MPS2 * total - sum(values)
    every_failed = bool(values) and min(values) < SHAKE_POSITIVE_THRESHOLD_MPS2 * (1 - HELD_LIMIT_TOLERANCE)
    cap = max(mean_needs, 0.0 if every_failed else SHAKE_POSITIVE_THRESHOLD_MPS2)
    return cap if cap < limit else None


def rms_speed_mps(before: list | None, after: list, dt_s: float) -> float:
    """RMS speed of the tracked points between two snapshots (0 when there is no comparable one)."""
    if before is None or [b.shape for b in before] != [a.shape for a in after] or dt_s <= 0:
        return 0.0
    moved = np.concatenate([a - b for a, b in zip(after, before)])
    return float(np.sqrt(np.mean(np.sum(moved ** 2, axis=1)))) / dt_s


def _confidently_decided(values, min_directions: int, margin_mps2: float) -> bool:
    """Surrogate stop: after >= min_directions directions, the measured mean is so far from the
    threshold (margin_mps2 / sqrt(k)) that the remaining directions, spread over the sphere by the
    bit-reversed order, are very unlikely to carry it across. Its label agreement with the full
    protocol is measured by bench/bench_datagen.py and bench/replay_confident_stop.py."""
    k = len(values)
    if k < min_directions:
        return False
    return abs(float(np.mean(values)) - SHAKE_POSITIVE_THRESHOLD_MPS2) >= margin_mps2 / math.sqrt(k)


def _axis_angle(axis, angle):
    axis = axis / np.linalg.norm(axis)
    k = np.array([[0, -axis[2], axis[1]], [axis[2], 0, -axis[0]], [-axis[1], axis[0], 0]])
    return np.eye(3) + math.sin(angle) * k + (1 - math.cos(angle)) * k @ k


def run_grasp_trial(spec: objects.ObjectSpec, grasp: WorldGrasp, tests=("shake",),
                    settings: TrialSettings | None = None, client: int | None = None,
                    object_xy_m=(0.0, 0.0), object_yaw_rad: float = 0.0) -> TrialOutcome:
    """Grasp `spec` (resting on the table at object_xy_m, object_yaw_rad) with `grasp`, lift, run `tests`.

    tests: any of "shake", "twist". Returns a TrialOutcome whose status is
    ok, lift_failed (a valid negative), exploded or timeout (simulation
    failures, never labels). Uses `client` (a DIRECT server) or its own.
    """
    settings = settings or TrialSettings()
    unknown = set(tests) - {"shake", "twist"}
    if unknown:
        raise ValueError(f"unknown tests {sorted(unknown)}; known: shake, twist")
    own = client is None
    client = world.connect() if own else client
    t0 = time.process_time()
    trial = None
    out = TrialOutcome(status=STATUS_OK, sim={"settings": settings.to_record()})
    try:
        trial = _Trial(client, spec, grasp, settings, object_xy_m, object_yaw_rad)
        out.grasp_force_n = trial.force_n
        out.sim.update(time_step_s=trial.world.time_step_s,
                       soft=[pt.soft for pt in trial.obj.parts], mass_kg=trial.obj.mass_kg,
                       protocol=settings.protocol.name, **trial.material.facts())
        trial.grasp_and_lift()
        out.sim.update(trial.protocol_facts())
        if "shake" in tests:
            out.shake_accels_mps2, out.shake_measured = trial.shake()
        if "twist" in tests:
            out.twist_accels_radps2, out.twist_measured = trial.twist()
    except _Abort as abort:
        out.status, out.note = abort.status, abort.note
    finally:
        out.cpu_s = time.process_time() - t0
        out.sim_steps = trial.steps if trial else 0
        if own:
            p.disconnect(client)
    return out
