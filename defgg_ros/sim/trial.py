"""One grasp trial: close, lift, shake test (16 directions) and twist test.

Protocol (paper + DefGraspSim): the hand closes with a force that grows with
log10(E) (grasp_force_n), lifts, then for each direction the acceleration is
ramped until the object is no longer held or the limit is reached; the held
value is recorded per direction. Positive when the mean is >=
SHAKE_POSITIVE_THRESHOLD_MPS2 (TrialRecord.label).

The shake uses the gravity trick measured in the FEM notes: the hand stays
still and gravity is set to g - a*d, which matched moving the hand within
0.1 m/s^2. The twist really rotates the hand (a non-uniform field cannot be
faked by gravity), one way or oscillating (TrialSettings.twist_oscillation_radps).
The grasp+lift state is shared by all directions:
saveState does not cover soft nodes, so LoadedObject.restore_state resets
the nodes with resetMeshData and zeroes their velocities.

Speed-ups (validated against TrialSettings.naive() in bench/bench_datagen.py).
Exact (the defaults, TrialSettings.exact()): stop a direction as soon as the
object is lost; stop the remaining directions once the label is decided (mean
can no longer reach, or can no longer miss, the threshold); skipped directions
are stored as the bound that decided the label (50 / 0). Surrogate (on in
TrialSettings.fast(), the generator's): after >= 4 directions stop when the
measured mean is far from the threshold; skipped directions hold the measured
mean. Skipped directions are flagged False in `shake_measured`. The evaluation's
exact stop (shake_stop_when_decided) also ends a direction's ramp once held at
the value that decides both its outcomes (shake_outcome_cap).
"""
from __future__ import annotations

import math
import time
from dataclasses import asdict, dataclass, field, replace

import numpy as np

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
from defgg_ros.grip_force import defgraspsim_finger_force_n, grasp_force_n
from defgg_ros.sim import hand as hand_mod
from defgg_ros.sim import objects, physics, world
from defgg_ros.sim.hand import world_T_hand

# Trial protocols (docs/dataset.md, "Trial protocols"). legacy: fem_v1-v4's (gravity on, grip force
# 2 N + 0.5 N per decade a finger, fingers force-held, lost when both fingers let go or the centroid moved
# 20 mm). defgraspsim: the protocol of the paper's labels (NVlabs/DefGraspSim): zero gravity once the
# object has settled, total grip force FOS * m * g / mu with FOS = 1 + log10(E) / 10, the table moved away
# for the pickup, fingers held after it (TrialSettings.finger_hold), lost as soon as either finger has no
# contact. Each protocol's material is in the physics core's table, physics.MATERIALS.
PROTOCOL_LEGACY = "legacy"
PROTOCOL_DEFGRASPSIM = "defgraspsim"
PROTOCOLS = (PROTOCOL_LEGACY, PROTOCOL_DEFGRASPSIM)
FINGER_HOLDS = ("force", "lock")
TABLE_AWAY_Z_M = -1.0   # where the defgraspsim pickup moves the table (DefGraspSim lowers its platform)

OPENING_CLEARANCE_M = 0.01      # fingers open this much wider than the grasp width (5 mm a side)
LOSS_DISTANCE_M = 0.02          # object moved this far relative to the hand = no longer held
# Confident stop (the surrogate): after k >= CONFIDENT_MIN_DIRECTIONS directions, stop when the
# measured mean is CONFIDENT_MARGIN_MPS2 / sqrt(k) from the threshold (k=3: >= 36.5 or <= 13.5;
# k=4: 35/15; k=8: 32.1/17.9). Tuned on the 402 soft trials of datasets fem_v1 + fem_v2 (every
# measured prefix replayed: 0 labels changed, shake steps -33 %), checked on bench/bench_datagen.py's
# naive sample. Until 2026-11-25 it was 40 and 4 (LEGACY_CONFIDENT_SETTINGS): 0 changes, -2 %.
CONFIDENT_MIN_DIRECTIONS = 3
CONFIDENT_MARGIN_MPS2 = 20.0
LEGACY_CONFIDENT_SETTINGS = {"confident_min_directions": 4, "confident_margin_mps2": 40.0}
LEGACY_TWIST_SETTINGS = {"twist_oscillation_radps": None}   # before 2026-11-25: the one-way twist
LEGACY_EVAL_STOP_SETTINGS = {"shake_stop_when_decided": False}   # before 2026-11-27: every direction measured
# Before 2026-11-26 every trial ran the legacy protocol on its own material.
LEGACY_PROTOCOL_SETTINGS = {"protocol": "legacy", "object_friction": None, "poisson_ratio": None,
                            "finger_hold": "force", "grip_force_friction": None}
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
    """Top-down grasp in the world frame: TCP position (m), yaw of the closing direction, width (m)."""
    position_m: tuple
    yaw_rad: float
    width_m: float

    def __post_init__(self):
        if not np.all(np.isfinite(self.position_m)) or len(self.position_m) != 3:
            raise ValueError(f"grasp position must be 3 finite numbers, got {self.position_m}")
        if not 0.0 < self.width_m <= GRIPPER_MAX_WIDTH_M:
            raise ValueError(f"grasp width {self.width_m} m outside (0, {GRIPPER_MAX_WIDTH_M}]")


# Until 2026-11-24 the lift took 0.3 s and the hold 0.1 s: soft grasps that the
# probe's 0.6 s lift holds fell out (capsule at 2e5 Pa: held 29 m/s^2 after the
# slow lift, lift failure after the fast one; bench/README.md). Datasets made
# with it record these values and resume with them (data/datagen.py).
LEGACY_LIFT_SETTINGS = {"lift_time_s": 0.3, "hold_time_s": 0.1}


@dataclass(frozen=True)
class TrialSettings:
    close_speed_mps: float = 0.1
    close_settle_s: float = 0.1
    settle_before_s: float = 0.02
    lift_height_m: float = 0.03
    lift_time_s: float = 0.6
    hold_time_s: float = 0.2
    shake_ramp_time_s: float = 0.5
    twist_ramp_time_s: float = 0.5
    # None: the twist's angular acceleration ramps one way (the hand spins up to 125 rad/s); a value
    # (rad/s): it oscillates at that angular frequency under the ramped amplitude (the evaluation's).
    twist_oscillation_radps: float | None = None
    check_every_s: float = 0.005
    stop_direction_when_lost: bool = True
    stop_when_label_decided: bool = True
    confident_stop: bool = False       # the validated surrogate (_confidently_decided); on in fast()
    confident_min_directions: int = CONFIDENT_MIN_DIRECTIONS
    confident_margin_mps2: float = CONFIDENT_MARGIN_MPS2
    max_cpu_s: float = 900.0
    # Evaluation tasks (defgg_ros/evaluation): ramp the shake only to this limit, and stop
    # the remaining directions/axes once one is held below *_fail_below_* (the task has
    # failed). Skipped ones are stored as 0 and flagged unmeasured. None = off (generator).
    shake_limit_mps2: float = SHAKE_ACCEL_LIMIT_MPS2
    shake_fail_below_mps2: float | None = None
    # The evaluation under the label's rule reports two outcomes, the mean held >= the threshold and "held in
    # every direction": stop the shake once both are certain (the mean as in stop_when_label_decided, and a
    # measured direction below the threshold), filling the rest as that stop does, and end a direction's ramp
    # once held at the value that decides both (shake_outcome_cap; stored as that lower bound, flagged
    # unmeasured). Exact: neither outcome changes.
    shake_stop_when_decided: bool = False
    twist_fail_below_radps2: float | None = None
    time_step_s: float | None = None   # None: world.time_step_for(E), the probe's stable steps
    shake_directions: int = SHAKE_DIRECTIONS   # fewer only in tests
    # PROTOCOLS; records made before the field existed are legacy (comparable_protocol).
    protocol: str = PROTOCOL_DEFGRASPSIM
    # Material overrides (None: the protocol's, physics.MATERIALS): the object's friction coefficient
    # (the pads' stays the protocol's) and Poisson's ratio.
    object_friction: float | None = None
    poisson_ratio: float | None = None
    # defgraspsim: how the fingers hold after the pickup. "force": each finger keeps pushing with F/2 (the
    # default: it keeps the squeeze DefGraspSim's locked joints keep); "lock": DefGraspSim's joint lock,
    # soft objects only. PyBullet's soft-rigid contact stores no penetration force, so a locked finger keeps
    # only what the object's own compression pushes back: 90 % of F/2 at 2e4 Pa, ~50 % at 2e5, 0 at 2e6 Pa
    # on box_small (bench/bench_finger_lock.py), which made stiff soft objects slip out as an artefact.
    finger_hold: str = "force"
    # defgraspsim: the friction coefficient the grip force rule F = FOS * m * g / mu divides by. None: the
    # effective friction, so mu * F = FOS * m * g whatever the friction (DefGraspSim's rule). A value above the
    # real friction squeezes as if the contact were grippier than it is: friction alone then holds less than
    # FOS * g and the rest must come from the grasp's geometry (pilot b, bench/pilots/README.md).
    grip_force_friction: float | None = None

    def __post_init__(self):
        if self.protocol not in PROTOCOLS:
            raise ValueError(f"unknown trial protocol {self.protocol!r}; known: {', '.join(PROTOCOLS)}")
        if self.object_friction is not None and not 0.0 < self.object_friction <= 2.0:
            raise ValueError(f"object_friction must be in (0, 2], got {self.object_friction}")
        if self.poisson_ratio is not None and not 0.0 <= self.poisson_ratio < 0.5:
            raise ValueError(f"poisson_ratio must be in [0, 0.5), got {self.poisson_ratio}")
        if self.grip_force_friction is not None and not 0.0 < self.grip_force_friction <= 2.0:
            raise ValueError(f"grip_force_friction must be in (0, 2], got {self.grip_force_friction}")
        if self.finger_hold not in FINGER_HOLDS:
            raise ValueError(f"finger_hold must be one of {', '.join(FINGER_HOLDS)}, got {self.finger_hold!r}")

    def material(self) -> dict:
        """finger_friction, object_friction, effective_friction (their product) and poisson_ratio."""
        material = physics.MATERIALS[self.protocol]
        if self.object_friction is not None:
            material = replace(material, object_friction=self.object_friction)
        if self.poisson_ratio is not None:
            material = replace(material, poisson_ratio=self.poisson_ratio)
        return {**asdict(material), "effective_friction": material.effective_friction}

    def grip_force_mu(self) -> float:
        """The mu of the defgraspsim force rule FOS*m*g/mu: the rule's own friction, else the contact's."""
        return self.grip_force_friction or self.material()["effective_friction"]

    @classmethod
    def naive(cls) -> TrialSettings:
        """The probe's protocol: close 0.4 s, lift 0.8 s, every direction ramps to the end, all 16 run."""
        return cls(close_settle_s=0.3, lift_time_s=0.6, hold_time_s=0.2, stop_direction_when_lost=False,
                   stop_when_label_decided=False)

    @classmethod
    def exact(cls) -> TrialSettings:
        """Only the stops that cannot change the label (no surrogate); the dataclass defaults."""
        return cls()

    @classmethod
    def fast(cls) -> TrialSettings:
        """The generator's protocol: exact stops plus the confident-stop surrogate."""
        return cls(confident_stop=True)

    @classmethod
    def from_record(cls, recorded: dict) -> TrialSettings:
        """The settings a trial record's `trial_settings` describe; fields it predates get the value they
        implicitly had then (a record without a protocol ran the legacy one)."""
        return cls(**{**LEGACY_PROTOCOL_SETTINGS, **recorded})

    @classmethod
    def legacy(cls) -> TrialSettings:
        """fem_v4's generator settings exactly (the legacy protocol, its confident stop)."""
        return cls(confident_stop=True, protocol=PROTOCOL_LEGACY)


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
    def __init__(self, client, spec, grasp, settings, object_xy_m, object_yaw_rad):
        self.client, self.grasp, self.settings = client, grasp, settings
        self.defgraspsim = settings.protocol == PROTOCOL_DEFGRASPSIM
        self.material = settings.material()
        if self.material["poisson_ratio"] is not None:
            spec = replace(spec, poisson_ratio=self.material["poisson_ratio"])
        self.spec = spec
        self.world = world.create_world(client, spec.part_moduli_pa(), settings.time_step_s)
        self.obj = objects.load_object(client, spec, object_xy_m, object_yaw_rad,
                                       friction=self.material["object_friction"])
        softest = min(spec.part_moduli_pa())
        if self.defgraspsim:
            self.force_n = defgraspsim_finger_force_n(softest, self.obj.mass_kg, settings.grip_force_mu())
            self.gravity = np.zeros(3)      # during the squeeze, the pickup and the tests
        else:
            self.force_n = grasp_force_n(softest)
            self.gravity = np.array([0.0, 0.0, -world.GRAVITY_MPS2])
        self.fingers_locked = False
        self.steps = 0
        self.last_points = None   # for the energy check; None after a restore (a deliberate jump)
        self.t0 = time.process_time()
        self.check_steps = max(1, round(settings.check_every_s / self.world.time_step_s))

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
        if time.process_time() - self.t0 > self.settings.max_cpu_s:
            raise _Abort(STATUS_TIMEOUT, f"trial exceeded {self.settings.max_cpu_s} s CPU")

    def seconds(self, t_s):
        return max(1, round(t_s / self.world.time_step_s))

    def grasp_and_lift(self):
        s = self.settings
        self.step(self.seconds(s.settle_before_s))      # settles under gravity on the table
        self.world.set_gravity(self.gravity)             # defgraspsim: zero before the fingers close
        opening = min(self.grasp.width_m + OPENING_CLEARANCE_M, GRIPPER_MAX_WIDTH_M)
        self.tcp = world_T_hand(self.grasp.position_m, self.grasp.yaw_rad)
        self.hand = hand_mod.create_hand(self.client, self.tcp, opening, friction=self.material["finger_friction"])
        self.hand.close(self.force_n, s.close_speed_mps)
        self.step(self.seconds(opening / 2 / s.close_speed_mps + s.close_settle_s))
        if self.hand.finger_opening_m() < 1e-3:
            raise _Abort(STATUS_LIFT_FAILED, "fingers closed on nothing")
        if self.defgraspsim:
            self._pickup_without_gravity()
        else:
            self._lift()
        self.ref_offset = self.object_in_hand()
        if not self.held():
            raise _Abort(STATUS_LIFT_FAILED, "object not held after lift")
        if self.defgraspsim:
            self.hold_fingers_for_tests()
        self.squeeze_after_pickup_n = self.hand.finger_forces_n()
        self.saved = (self.obj.save_state(), self.hand.save_state())

    def hold_fingers_for_tests(self):
        """defgraspsim: with finger_hold "lock", lock the fingers on a soft object. A rigid body stores no
        elastic squeeze: between locked fingers it kept ~1e-4 N and slid off (an artefact), so the rigid
        stand-in of 2e9 Pa stays held with force F/2 in any case (bench/bench_finger_lock.py)."""
        if self.settings.finger_hold == "lock" and all(pt.soft for pt in self.obj.parts):
            self.hand.lock_fingers()
            self.fingers_locked = True
            self.step(self.check_steps)

    def _lift(self):
        """legacy: lift the object off the table with a smooth 0.6 s profile, then hold."""
        s = self.settings
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
        """defgraspsim: the squeeze has settled; move the table away and hold (the hand stays put)."""
        self.world.move_table(TABLE_AWAY_Z_M)
        self.step(self.seconds(self.settings.hold_time_s))
        self.lifted_tcp = self.tcp.copy()

    def protocol_facts(self) -> dict:
        """What the trial really did, read back from the engine after the pickup (recorded per trial)."""
        return {"gravity_during_test_mps2": self.world.gravity(), "finger_force_set_n": self.force_n,
                "fingers_locked": self.fingers_locked,
                "squeeze_after_pickup_n": [round(f, 6) for f in self.squeeze_after_pickup_n],
                "loss_rule": "either_finger" if self.defgraspsim else "both_fingers_or_20mm"}

    def held(self) -> bool:
        contacts = np.sum([self.hand.finger_contacts(b) for b in self.obj.body_ids], axis=0)
        if self.defgraspsim:                 # lost as soon as either finger has no contact
            return bool(np.all(contacts > 0))
        if not contacts.any():
            return False
        return float(np.linalg.norm(self.object_in_hand() - self.ref_offset)) < LOSS_DISTANCE_M

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
                if self.settings.stop_direction_when_lost:
                    break
            if not lost and stop_at is not None and value >= stop_at:
                return value
        return held_value

    def shake(self):
        g = self.gravity
        dirs = shake_directions(self.settings.shake_directions)
        values, measured = [], []
        for d in dirs:
            self.restore()

            def apply(a, n, d=d):
                self.world.set_gravity(g - a * d)
                self.step(n)

            cap = self._shake_outcome_cap(values, len(dirs))
            values.append(self.ramp(self.settings.shake_limit_mps2, self.settings.shake_ramp_time_s, apply, cap))
            measured.append(cap is None or values[-1] < cap)    # a capped direction holds a lower bound
            left = len(dirs) - len(values)
            if self.settings.confident_stop and left and _confidently_decided(
                    values, self.settings.confident_min_directions, self.settings.confident_margin_mps2):
                values += [float(np.mean(values))] * left    # imputed by the measured mean
                measured += [False] * left
                break
            fail_below = self.settings.shake_fail_below_mps2
            if fail_below is not None and values[-1] < fail_below and left:
                values += [0.0] * left
                measured += [False] * left
                break
            fill = label_decided_fill(values, len(dirs), SHAKE_POSITIVE_THRESHOLD_MPS2, SHAKE_ACCEL_LIMIT_MPS2) \
                if self.settings.stop_when_label_decided or self._both_outcomes_may_stop(values) else None
            if fill is not None:
                values += [fill] * left
                measured += [False] * left
                break
        self.world.set_gravity(g)
        return values, measured

    def _shake_outcome_cap(self, values, total: int) -> float | None:
        if not self.settings.shake_stop_when_decided:
            return None
        return shake_outcome_cap(values, total, self.settings.shake_limit_mps2)

    def _both_outcomes_may_stop(self, values) -> bool:
        """shake_stop_when_decided: the every-direction outcome is certain (a measured direction was not held
        at the threshold), so the shake may stop as soon as the mean's is too."""
        every_failed = min(values) < SHAKE_POSITIVE_THRESHOLD_MPS2 * (1 - HELD_LIMIT_TOLERANCE)
        return self.settings.shake_stop_when_decided and every_failed

    def twist(self):
        values, fill = [], 0.0     # axes skipped after a failure hold 0
        osc = self.settings.twist_oscillation_radps
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

            values.append(self.ramp(TWIST_ACCEL_LIMIT_RADPS2, self.settings.twist_ramp_time_s, apply))
            fail_below = self.settings.twist_fail_below_radps2
            if fail_below is not None and values[-1] < fail_below:
                break
            decided = label_decided_fill(values, len(TWIST_AXES), TWIST_POSITIVE_THRESHOLD_RADPS2,
                                         TWIST_ACCEL_LIMIT_RADPS2) if self.settings.stop_when_label_decided else None
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


def comparable_protocol(recorded: dict) -> dict:
    """A recorded TrialSettings dict in the form two protocols are compared in (resuming a dataset or an
    evaluation folder): fields added after it was recorded get the value they implicitly had then
    (LEGACY_CONFIDENT_SETTINGS, LEGACY_TWIST_SETTINGS, LEGACY_PROTOCOL_SETTINGS, LEGACY_EVAL_STOP_SETTINGS),
    and the surrogate's knobs drop out when the surrogate is off."""
    full = {**LEGACY_CONFIDENT_SETTINGS, **LEGACY_TWIST_SETTINGS, **LEGACY_PROTOCOL_SETTINGS,
            **LEGACY_EVAL_STOP_SETTINGS, **recorded}
    if not full.get("confident_stop"):
        for key in LEGACY_CONFIDENT_SETTINGS:
            full.pop(key)
    return full


# The fields that make a trial protocol setting (a pilot's or a dataset's): the protocol and its material and
# grip force overrides. The evaluation takes them from the training data (defgg-eval run --protocol-from).
PROTOCOL_SETTING_FIELDS = ("protocol", "object_friction", "poisson_ratio", "finger_hold", "grip_force_friction")


def protocol_setting(recorded: dict) -> dict:
    """The PROTOCOL_SETTING_FIELDS of a recorded TrialSettings dict (fields it predates: their old value)."""
    full = {**LEGACY_PROTOCOL_SETTINGS, **recorded}
    return {k: full[k] for k in PROTOCOL_SETTING_FIELDS}


def task_protocol(recorded: dict, task: str) -> dict:
    """comparable_protocol of the settings `task` reads: the other task's own settings (shake_* for the
    twist, twist_* for the shake) drop out, so a new twist ramp does not make a folder's shake trials
    another protocol."""
    other = {"shake": "twist_", "twist": "shake_"}[task]
    return {k: v for k, v in comparable_protocol(recorded).items() if not k.startswith(other)}


def protocol_differences(records, settings: dict, task: str) -> list:
    """The settings (sorted names) in which the first of `records`' `task` trials whose task_protocol
    differs from that of `settings` differs; [] when all match. Records carry their trial_settings."""
    new = task_protocol(settings, task)
    for r in records:
        if r["task"] == task:
            old = task_protocol(r["trial_settings"], task)
            differ = sorted(k for k in set(old) | set(new) if old.get(k) != new.get(k))
            if differ:
                return differ
    return []


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
    out = TrialOutcome(status=STATUS_OK, sim={"settings": asdict(settings)})
    try:
        trial = _Trial(client, spec, grasp, settings, object_xy_m, object_yaw_rad)
        out.grasp_force_n = trial.force_n
        out.sim.update(time_step_s=trial.world.time_step_s,
                       soft=[pt.soft for pt in trial.obj.parts], mass_kg=trial.obj.mass_kg,
                       protocol=settings.protocol, **trial.material)
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
            import pybullet as p

            p.disconnect(client)
    return out
