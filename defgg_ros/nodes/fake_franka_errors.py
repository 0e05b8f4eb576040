"""The simulated driver's robot errors: a reflex ends control as franka_ros2 3.x does, and the recovery brings it back.

franka_ros2 v3.3.0+ on an FCI error (docs/franka_contract.md, "Robot errors"): the hardware plugin logs libfranka's
exception, stops the robot and returns ERROR from `read`; the controller manager takes the hardware component to
unconfigured and deactivates every controller that uses its interfaces: the arm's trajectory controller (its goal
aborts, goals are rejected) and both broadcasters (franka/joint_states, the external wrench, current_pose and
measured_joint_states go quiet; joint_state_publisher goes on republishing the arm's last state with new stamps).
Recovery, in order: `action_server/error_recovery` (franka_msgs/action/ErrorRecovery) clears the error, the
controller manager's `set_hardware_component_state` takes FrankaHardwareInterface to active, `switch_controller`
activates the controllers. The simulated reflex: the contact force on the hand above `reflex_force_n`.

Threads: `check_reflex` runs in the sim thread with the driver's lock held; the services and the action in ROS
callbacks, which take the lock.
"""
import collections
import math

from controller_manager_msgs.msg import ControllerState
from controller_manager_msgs.srv import ListControllers, SetHardwareComponentState, SwitchController
from franka_msgs.action import ErrorRecovery
from lifecycle_msgs.msg import State
from rclpy.action import ActionServer, CancelResponse, GoalResponse

from defgg_ros.ros import topics

# libfranka's ControlException text for a Cartesian collision reflex (the form of its "motion aborted by reflex!"
# message; the simulated driver logs it with the force that fired it).
REFLEX_TEXT = 'libfranka: Move command aborted: motion aborted by reflex! ["cartesian_reflex"]'
CONTROLLER_TYPES = {topics.JOINT_STATE_BROADCASTER: "joint_state_broadcaster/JointStateBroadcaster",
                    topics.ROBOT_STATE_BROADCASTER: "franka_robot_state_broadcaster/FrankaRobotStateBroadcaster"}
ARM_CONTROLLER_TYPE = "joint_trajectory_controller/JointTrajectoryController"
CONTROLLER_UPDATE_RATE_HZ = 1000   # franka_bringup/config/controllers.yaml update_rate
# The reflex reads the contact force averaged over this window, not one physics step's: PyBullet reports an impact as
# its impulse over one 1 ms step (a held block touching the bin floor: 74.6 N for the step, a replayed session,
# 2026-12-03), while the robot's reflex acts on its external force estimate (its filtering is not in franka_ros2's or
# libfranka's sources; a pressing hand's force lasts far longer than this window).
REFLEX_WINDOW_S = 0.01
STATE_LABELS = {State.PRIMARY_STATE_UNCONFIGURED: "unconfigured", State.PRIMARY_STATE_INACTIVE: "inactive",
                State.PRIMARY_STATE_ACTIVE: "active", State.PRIMARY_STATE_FINALIZED: "finalized"}
STATE_IDS = {label: state_id for state_id, label in STATE_LABELS.items()}


class FakeControllerManager:
    """The hardware component's and the controllers' lifecycle states of the simulated driver, its reflex and the
    recovery's three interfaces. The driver asks `publishes(broadcaster)` before it publishes a broadcaster's topic."""

    def __init__(self, driver, arm, arm_controller: str, callback_group):
        self._driver, self._arm, self._lock = driver, arm, driver._lock
        self._logger = driver.get_logger()
        self.reflex_force_n = float(driver.cfg["reflex_force_n"])
        self.hardware_state = "active"
        self.robot_error = ""     # libfranka's error until error recovery clears it
        self.reflexes = 0
        self.peak_force_n = 0.0   # the largest windowed force since the driver's last log (it resets it)
        self.peak_raw_force_n = 0.0   # the same for one step's force
        periods = max(1, round(REFLEX_WINDOW_S * float(driver.cfg["robot_state_rate_hz"])))
        self._window = collections.deque(maxlen=periods)   # the last periods' forces (tuples, N)
        self._window_sum = [0.0, 0.0, 0.0]
        self._arm_controller = arm_controller
        self.controllers = dict.fromkeys((topics.JOINT_STATE_BROADCASTER, topics.ROBOT_STATE_BROADCASTER,
                                          arm_controller), "active")
        driver.create_service(ListControllers, topics.LIST_CONTROLLERS_SERVICE, self._on_list,
                              callback_group=callback_group)
        driver.create_service(SwitchController, topics.SWITCH_CONTROLLER_SERVICE, self._on_switch,
                              callback_group=callback_group)
        driver.create_service(SetHardwareComponentState, topics.SET_HARDWARE_STATE_SERVICE, self._on_set_hardware,
                              callback_group=callback_group)
        ActionServer(driver, ErrorRecovery, topics.ERROR_RECOVERY_ACTION, execute_callback=self._recover,
                     callback_group=callback_group, goal_callback=lambda _goal: GoalResponse.ACCEPT,
                     cancel_callback=lambda _goal: CancelResponse.ACCEPT)

    def publishes(self, controller: str) -> bool:
        return self.controllers[controller] == "active"

    # ---- the sim thread (lock held) ------------------------------------------
    def check_reflex(self, force_on_hand_n) -> None:
        """A reflex when the external force, averaged over REFLEX_WINDOW_S, exceeds reflex_force_n while the
        hardware runs (called once per control period)."""
        if self.hardware_state != "active":
            return
        # Plain floats: np.linalg.norm here (its np.dot gives the GIL up each call and waits to get it back behind
        # the process's other threads) made the e2e pick fail 6 of 7 runs, the driver's joint states stalling 10-30 s.
        force = tuple(float(v) for v in force_on_hand_n)
        if len(self._window) == self._window.maxlen:
            oldest = self._window[0]
            self._window_sum = [total - old for total, old in zip(self._window_sum, oldest)]
        self._window.append(force)
        self._window_sum = [total + new for total, new in zip(self._window_sum, force)]
        force_n = math.hypot(*self._window_sum) / self._window.maxlen
        self.peak_force_n = max(self.peak_force_n, force_n)
        self.peak_raw_force_n = max(self.peak_raw_force_n, math.hypot(*force))
        if 0 < self.reflex_force_n < force_n:
            self.reflexes += 1
            self._robot_error(f"{REFLEX_TEXT} (simulated: external force {force_n:.1f} N over "
                              f"{REFLEX_WINDOW_S * 1e3:g} ms, over reflex_force_n {self.reflex_force_n:g} N)")

    def _robot_error(self, error: str) -> None:
        self.robot_error = error
        self._window.clear()   # the reactivated hardware starts a new estimate
        self._window_sum = [0.0, 0.0, 0.0]
        self._logger.error(error)
        self.hardware_state = "unconfigured"
        deactivated = [name for name, state in self.controllers.items() if state == "active"]
        for name in deactivated:
            self.controllers[name] = "inactive"
        self._arm.deactivate()   # the robot stopped: its controller holds where it is and takes no goal
        self._logger.error("Deactivating following hardware components as their read cycle resulted in an error: "
                           f"[ {topics.FRANKA_HARDWARE_COMPONENT} ]")
        self._logger.error("Deactivating following controllers as their hardware components read cycle resulted "
                           f"in an error: [ {' '.join(deactivated)} ]")

    # ---- the recovery (ROS threads) ------------------------------------------
    def _recover(self, goal_handle):
        """error_recovery: libfranka's automaticErrorRecovery clears the robot's error (it succeeds without one)."""
        with self._lock:
            cleared, self.robot_error = self.robot_error, ""
        self._logger.info("Automatic recovery succeeded" + (f" (cleared: {cleared})" if cleared else ""))
        goal_handle.succeed()
        return ErrorRecovery.Result()

    def _on_set_hardware(self, request, response):
        target = request.target_state.label or STATE_LABELS.get(request.target_state.id, "")
        with self._lock:
            if request.name != topics.FRANKA_HARDWARE_COMPONENT:
                self._logger.error(f"hardware component {request.name!r} is unknown: this cell has "
                                   f"{topics.FRANKA_HARDWARE_COMPONENT!r}")
                response.ok = False
            elif target != "active":
                self._logger.error(f"the simulated driver takes its hardware to 'active' only, not {target!r}")
                response.ok = False
            elif self.robot_error:   # the hardware cannot reconnect to a robot in error: recovery first
                self._logger.error(f"cannot activate {request.name}: the robot is in error ({self.robot_error}); "
                                   f"call {topics.ERROR_RECOVERY_ACTION} first")
                response.ok = False
            else:
                self.hardware_state, response.ok = "active", True
            response.state = self._hardware_state_msg()
        return response

    def _hardware_state_msg(self) -> State:
        return State(id=STATE_IDS[self.hardware_state], label=self.hardware_state)

    def _on_switch(self, request, response):
        """switch_controller: STRICT fails on any problem; best effort (also strictness 0, the manager's default)
        switches what it can and fails only when nothing was to be switched."""
        strict = request.strictness == SwitchController.Request.STRICT
        names = [*request.activate_controllers, *request.deactivate_controllers]
        with self._lock:
            problems = [f"controller {name!r} is not loaded" for name in names if name not in self.controllers]
            activate = [n for n in request.activate_controllers if self.controllers.get(n) == "inactive"]
            deactivate = [n for n in request.deactivate_controllers if self.controllers.get(n) == "active"]
            if strict:
                problems += [f"Controller with name '{name}' is already active." for name in
                             request.activate_controllers if self.controllers.get(name) == "active"]
            if activate and self.hardware_state != "active":
                problems.append(f"cannot activate {', '.join(activate)}: hardware component "
                                f"{topics.FRANKA_HARDWARE_COMPONENT} is {self.hardware_state}")
                activate = []
            if problems and (strict or not (activate or deactivate)):
                response.ok, response.message = False, "; ".join(problems)
                self._logger.error(response.message)
                return response
            for name in deactivate:
                self._set_controller(name, "inactive")
            for name in activate:
                self._set_controller(name, "active")
            response.ok, response.message = True, "; ".join(problems) or "switched"
        return response

    def _set_controller(self, name: str, state: str) -> None:
        self.controllers[name] = state
        if name == self._arm_controller:
            (self._arm.activate if state == "active" else self._arm.deactivate)()

    def _on_list(self, _request, response):
        with self._lock:
            states = dict(self.controllers)
        response.controller = [
            ControllerState(name=name, state=state, type=CONTROLLER_TYPES.get(name, ARM_CONTROLLER_TYPE),
                            update_rate=CONTROLLER_UPDATE_RATE_HZ) for name, state in states.items()]
        return response
