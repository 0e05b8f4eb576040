"""Every number the paper (Le et al., Deformation-Aware Data-Driven Grasp
Synthesis) or the Panda hardware fixes, in one place.

Import from here; do not repeat these literals elsewhere.
"""
import math

# --- Materials (paper, Sec. "Dataset": four moduli from 2e4 to 2e9 Pa) -----
TRAINING_YOUNGS_MODULI_PA = (2e4, 2e5, 2e6, 2e9)
POISSON_RATIO = 0.4
# The stiffness encoding is continuous on a log scale over this range; any
# modulus inside it is valid input (sensitivity analysis, multi-material).
YOUNGS_MODULUS_MIN_PA = 1e3
YOUNGS_MODULUS_MAX_PA = 1e10
# Encoded value of background pixels; objects encode into [OBJECT_MIN, 1] so
# the network can always tell "no object" from "very soft object".
STIFFNESS_BACKGROUND = 0.0
STIFFNESS_OBJECT_MIN = 0.1
# PyBullet's FEM was unstable for E >= 2e7 Pa on these machines (see
# docs/dataset.md); stiffer materials are simulated as rigid bodies.
MAX_SOFT_BODY_YOUNGS_MODULUS_PA = 1e7
# One density for every object of the trials (water-like, as the FEM probe's 96 g box; DefGraspSim's is
# 1000 too): the defgraspsim labels' grip force used m = volume x this, so the cell estimates m the same way.
OBJECT_DENSITY_KG_M3 = 1000.0

# --- Grasp quality labels (paper: shake test) ------------------------------
SHAKE_DIRECTIONS = 16
SHAKE_ACCEL_LIMIT_MPS2 = 50.0
SHAKE_POSITIVE_THRESHOLD_MPS2 = 25.0
# The ramp records the last value it checked before a loss; a value within this fraction of a limit counts as
# "held at the limit" (ramp granularity; the evaluation's success rules and the trial's stops share it).
HELD_LIMIT_TOLERANCE = 1e-6
TWIST_ACCEL_LIMIT_RADPS2 = 500.0
# The twist part of the pilots' shake_and_twist label (data/signal.py): mean held angular acceleration
# over the six axes >= half the paper's 500 rad/s^2 limit.
TWIST_POSITIVE_THRESHOLD_RADPS2 = 250.0
GRASP_CANDIDATES_PER_OBJECT = 200
EVAL_GRASPS_PER_OBJECT = 5

# --- Network I/O (GG-CNN representation) -----------------------------------
NETWORK_INPUT_SIZE_PX = 300
# Width maps are normalised by 150 px (paper: W in [0, 150] pixels).
WIDTH_SCALE_PX = 150.0
ANGLE_MIN_RAD = -math.pi / 2
ANGLE_MAX_RAD = math.pi / 2

# --- Franka Panda hand ------------------------------------------------------
GRIPPER_MAX_WIDTH_M = 0.08
FINGER_DEPTH_M = 0.018      # finger pad length along the approach axis
FINGER_PAD_WIDTH_M = 0.02   # finger pad extent across the closing direction
GRIPPER_MAX_FORCE_N = 70.0  # continuous grasp force of the Franka Hand

# --- Pick-and-place sequence (paper, real-robot experiment) ----------------
PREGRASP_HEIGHT_M = 0.025

# --- Franka Panda arm limits (Franka's published datasheet) ----------------
PANDA_JOINT_NAMES = tuple(f"panda_joint{i}" for i in range(1, 8))
PANDA_FINGER_JOINT_NAMES = ("panda_finger_joint1", "panda_finger_joint2")
PANDA_Q_MIN_RAD = (-2.8973, -1.7628, -2.8973, -3.0718, -2.8973, -0.0175, -2.8973)
PANDA_Q_MAX_RAD = (2.8973, 1.7628, 2.8973, -0.0698, 2.8973, 3.7525, 2.8973)
PANDA_QD_MAX_RADPS = (2.1750, 2.1750, 2.1750, 2.1750, 2.6100, 2.6100, 2.6100)
PANDA_QDD_MAX_RADPS2 = (15.0, 7.5, 10.0, 12.5, 15.0, 20.0, 20.0)
PANDA_QDDD_MAX_RADPS3 = (7500.0, 3750.0, 5000.0, 6250.0, 7500.0, 10000.0, 10000.0)
# The arm controller's PID gains (p N*m/rad, d N*m*s/rad; i = 0) per joint 1..7 on the effort interface:
# franka_fr3_moveit_config/config/fr3_ros_controllers.yaml (franka_ros2 v3.4.0), as in
# sim_bringup/config/franka/controllers.yaml. The robot adds its own gravity compensation (libfranka's torque
# command excludes gravity), so these springs are all that holds the arm on its trajectory.
FRANKA_JTC_GAINS_PD = ((600.0, 30.0), (600.0, 30.0), (600.0, 30.0), (600.0, 30.0), (250.0, 10.0), (150.0, 10.0),
                       (50.0, 5.0))
# --- Franka Research 3 (FR3) arm limits (Franka's FR3 datasheet, "Limits for Franka Research 3") ------
# The same kinematic structure as the Panda, other ranges: joint 6 stays above 0.5445 rad, joint 4 below
# -0.1518 rad. Near the ends of a joint's range the FR3's controller also lowers the velocity bound:
# FR3_VELOCITY_ENVELOPE below.
FR3_Q_MIN_RAD = (-2.7437, -1.7837, -2.9007, -3.0421, -2.8065, 0.5445, -3.0159)
FR3_Q_MAX_RAD = (2.7437, 1.7837, 2.9007, -0.1518, 2.8065, 4.5169, 3.0159)
FR3_QD_MAX_RADPS = (2.62, 2.62, 2.62, 2.62, 5.26, 4.18, 5.26)
FR3_QDD_MAX_RADPS2 = (10.0, 10.0, 10.0, 10.0, 10.0, 10.0, 10.0)
FR3_QDDD_MAX_RADPS3 = (5000.0, 5000.0, 5000.0, 5000.0, 5000.0, 5000.0, 5000.0)
# The FR3's velocity bound as a function of the joint position (libfranka's rate_limiting.h,
# computeUpper/LowerLimitsJointVelocity, after Franka's "Limits for Franka Research 3"): per joint
#   upper(q) = min(v_max, max(0, -offset + sqrt(max(0, k * (q_upper - q)))))
#   lower(q) = max(-v_max, min(0, offset - sqrt(max(0, k * (q - q_lower)))))
# so a joint must brake at no more than k/2 rad/s^2 towards q_upper/q_lower and be still offset^2/k before them
# (for joints 1, 4 and 6 that is a few mrad inside the range ends above).
# Rows: (v_max rad/s, offset rad/s, k rad/s^2, q_upper rad, q_lower rad), joints 1..7. docs/real_cell.md.
FR3_VELOCITY_ENVELOPE = (
    (2.62, 0.30, 12.0, 2.75010, -2.75010),
    (2.62, 0.20, 5.17, 1.79180, -1.79180),
    (2.62, 0.20, 7.00, 2.90650, -2.90650),
    (2.62, 0.30, 8.00, -0.14580, -3.04810),
    (5.26, 0.35, 34.0, 2.81010, -2.81010),
    (4.18, 0.35, 11.0, 4.52050, 0.54092),
    (5.26, 0.35, 34.0, 3.01960, -3.01960),
)
# Arm models whose controller bounds the velocity by position (the Panda's bound is the constant one).
ARM_VELOCITY_ENVELOPES = {"fr3": FR3_VELOCITY_ENVELOPE}
# The FR3's range for goals (the IK's): the datasheet's, cut where the bound above is already 0 towards the end
# (q_upper - offset^2/k, q_lower + offset^2/k): a goal there cannot be approached at any speed, so the IK must not
# pick one (goals just inside may still need gentler braking than the plan's: check_trajectory refuses those).
# Joints 1, 4 and 6 lose 1.1, 5.3 and 7.5 mrad at each end; the others none. Trajectories are checked
# against the datasheet range (an arm at rest in the band may move out of it; moving in, the bound refuses).
FR3_GOAL_Q_MIN_RAD = tuple(max(q, lo + off ** 2 / k)
                           for q, (_, off, k, _, lo) in zip(FR3_Q_MIN_RAD, FR3_VELOCITY_ENVELOPE))
FR3_GOAL_Q_MAX_RAD = tuple(min(q, up - off ** 2 / k)
                           for q, (_, off, k, up, _) in zip(FR3_Q_MAX_RAD, FR3_VELOCITY_ENVELOPE))
# Per arm model (the executor's joint_limits): position min, max, velocity, acceleration, jerk.
ARM_JOINT_LIMITS = {
    "panda": (PANDA_Q_MIN_RAD, PANDA_Q_MAX_RAD, PANDA_QD_MAX_RADPS, PANDA_QDD_MAX_RADPS2, PANDA_QDDD_MAX_RADPS3),
    "fr3": (FR3_Q_MIN_RAD, FR3_Q_MAX_RAD, FR3_QD_MAX_RADPS, FR3_QDD_MAX_RADPS2, FR3_QDDD_MAX_RADPS3),
}
# Per arm model: the range the IK chooses goals in (min, max).
ARM_GOAL_RANGES = {"panda": (PANDA_Q_MIN_RAD, PANDA_Q_MAX_RAD), "fr3": (FR3_GOAL_Q_MIN_RAD, FR3_GOAL_Q_MAX_RAD)}
ARM_MODELS = tuple(ARM_JOINT_LIMITS)
# A comfortable "ready" configuration above the table.
PANDA_READY_Q_RAD = (0.0, -0.785, 0.0, -2.356, 0.0, 1.571, 0.785)

# --- Top-down depth camera (RealSense D435 depth stream, 640x480) ----------
# Training scenes are rendered with the same focal length and height above
# the table as the cell's camera, so a 300x300 crop means the same metric
# field of view (~0.31 m at 0.40 m) in both.
CAMERA_WIDTH_PX = 640
CAMERA_HEIGHT_PX = 480
CAMERA_FX_PX = 385.0
CAMERA_FY_PX = 385.0
CAMERA_HEIGHT_ABOVE_TABLE_M = 0.40
CAMERA_NEAR_M = 0.05
# The D435's colour stream at 640x480 (what the simulated driver renders with publish_color): the D400 datasheet's
# RGB field of view is 69 deg horizontal at 16:9 (1920 px), fx = 960 / tan(34.5 deg) = 1397 px; 640x480 is the
# sensor's 4:3 middle scaled by 4/9: 621 px. The colour camera sits 15 mm along camera_link's +y from the depth
# origin (realsense2_description's _d435.urdf.xacro, d435_cam_depth_to_color_offset; a device's own extrinsics
# differ by a fraction of a mm and a fraction of a degree).
COLOR_FX_PX = 621.0
COLOR_FY_PX = 621.0
LINK_COLOR_OFFSET_M = (0.0, 0.015, 0.0)
CAMERA_FAR_M = 2.0

# --- Franka Panda kinematics (Franka's datasheet / franka_ros defaults) ----
# Default TCP of the Franka Hand: fingertip centre, 0.1034 m along link8's z;
# the hand is turned -45 deg about that z (panda_hand_joint).
PANDA_TCP_OFFSET_M = 0.1034
PANDA_HAND_YAW_RAD = -math.pi / 4
# Our TCP frame's x axis is the fingers' closing axis (grasps are given as "close along x"). The
# fingers slide along the hand's y axis (panda_finger_joint1: axis 0 1 0), so the TCP is the hand
# frame turned a further +90 deg about z. (Until 2026-11-23 it was the hand frame itself: every
# grasp was executed 90 deg from the planned closing direction; square boxes hid it.)
PANDA_TCP_YAW_RAD = PANDA_HAND_YAW_RAD + math.pi / 2
# Datasheet reach (joint 2 axis to the flange) of the Panda.
PANDA_MAX_REACH_M = 0.855
PANDA_SHOULDER_HEIGHT_M = 0.333  # joint 2 axis above panda_link0

# --- Franka Hand geometry for simulation (from Franka's hand/finger meshes) -
# The hand frame used in simulation has its origin at the TCP (between the
# finger pads), x along the closing direction, z up (away from the object).
PANDA_HAND_PALM_SIZE_M = (0.204, 0.063, 0.066)  # along closing, across, height
PANDA_FINGER_LENGTH_M = 0.054        # finger from palm to tip
PANDA_FINGER_THICKNESS_M = 0.014     # finger pad thickness along the closing direction
PANDA_FINGERTIP_BELOW_TCP_M = 0.007  # fingertip end below the TCP (tip at 0.112, TCP at 0.105)
TABLE_CLEARANCE_M = 0.003            # fingertips stay this far above the table
# TCP height of an executed top-down grasp, as a fraction of the object height seen at the grasp
# centre (grasping.geometry.tcp_height_m). The image-space grasp has no height of its own.
GRASP_HEIGHT_FRACTION = 0.5
# The palm's underside stays this far above the surface seen at the grasp centre (tcp_height_m raises the
# TCP on an object taller than 2 x (finger length - fingertip offset - this) = 9.1 cm: ycb_bottle, 11 cm; the
# tallest evaluation object, common_can, is 9 cm, so the evaluation's grasps do not move). The sampler's
# PyBullet check (0.5 mm tolerance) still saw the palm touch ycb_bottle's top at 1.0 mm, not at 1.5 mm.
PALM_CLEARANCE_M = 0.0015
# Where a training candidate's TCP goes (sim.sampler): "contacts" = at the sampled contacts' height
# (the datasets up to fem_v3), "executor" = at tcp_height_m, the height the evaluation executes a grasp at.
GRASP_HEIGHT_RULES = ("contacts", "executor")

# --- Simulation -------------------------------------------------------------
GRAVITY_MPS2 = 9.81
# Outcome of a simulated grasp trial. Only "ok" and "lift_failed" become labels; simulation failures
# (exploded, timeout) are recorded but never used for training or counted as grasp outcomes.
STATUS_OK = "ok"
STATUS_LIFT_FAILED = "lift_failed"
STATUS_EXPLODED = "exploded"
STATUS_TIMEOUT = "timeout"

# An object more than this under the table top (z = 0) has left the table: fallen off an edge, or through
# the top when its FEM simulation failed (the fake driver reports it, the demo's table says so).
OFF_TABLE_DEPTH_M = 0.05
