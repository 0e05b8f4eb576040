"""The executor node's grasp: the goal's own, or planned by the grasp service on a frame the arm is not in.

A plan_grasp goal first brings the arm to the observation pose (ObservationMove), then plans only on a frame
taken after it rested there (and after the last squeeze's modulus reached the segmentation node); a best grasp
the sequence would refuse gives way to the next of plan_grasp_alternatives ranked grasps.
"""
import dataclasses
import time

from defgg_interfaces.srv import PlanGrasp

from defgg_ros.control.pick_place import ObservationMove, PickPlaceSequence
from defgg_ros.control.sequence_types import SqueezeRequest
from defgg_ros.nodes.executor_messages import GoalError, grasp_target
from defgg_ros.ros.conversions import stamp_to_ns
from defgg_ros.ros.service import ServiceTimeout, call_idempotent
from defgg_ros.squeeze import HandCalibration


class GraspPlanning:
    """The goal's grasp and its sequence (mixed into ExecutorNode)."""

    def _resolve_grasp(self, request):
        if not request.plan_grasp:
            return request.grasp
        return self._planned_grasps(1)[0]

    def _planned_grasps(self, top_k: int) -> list:
        """The grasp service's top_k grasps (best first, at least one) on a frame taken while the arm rested at
        the observation pose."""
        p = self._params()
        if not self._plan_client.wait_for_service(timeout_sec=p["server_wait_s"]):
            raise GoalError(f"grasp service {p['plan_grasp_service']} is not available")
        # Only a grasp from a frame taken while the arm rested at the observation pose: an older frame
        # may show the arm (after a cancel it stood over the table), and a grasp on it lands on the hand.
        deadline = time.monotonic() + float(p["fresh_frame_timeout_s"])
        while True:
            try:  # planning on the latest frame is idempotent: re-sent while unanswered (ros_service.py)
                response = call_idempotent(self._plan_client, PlanGrasp.Request(top_k=top_k),
                                           p["plan_grasp_timeout_s"], "grasp service")
            except (ServiceTimeout, RuntimeError) as error:
                raise GoalError(str(error)) from None
            grasp = response.grasps[0] if response.success and response.grasps else None
            frame_s = stamp_to_ns(grasp.header.stamp) * 1e-9 if grasp is not None else None
            with self._lock:
                clear = frame_s is not None and self._watch.frame_is_clear(frame_s)
                arrived_s = self._watch.since_s
            if clear:
                return list(response.grasps)
            if arrived_s is None:
                raise GoalError("not planning: the arm left the observation pose, so it may be in the camera's view")
            if time.monotonic() >= deadline:
                if grasp is not None:
                    raise GoalError(f"not planning on a view with the arm in it: no camera frame taken after the "
                                    f"arm reached the observation pose within {p['fresh_frame_timeout_s']:.0f} s "
                                    f"(newest frame {arrived_s - frame_s:.1f} s older)")
                raise GoalError(f"grasp planning failed: {response.message or 'no grasp returned'}")
            if self._shutdown.wait(0.5):  # the camera's next frame is on its way (each try runs the network)
                raise GoalError("executor is shutting down")

    def _observe_before_planning(self, goal_handle):
        """Bring the arm to the observation pose unless it rests there; the move's outcome (None: no move)."""
        with self._lock:
            if self._watch.at_observation():
                return None
        config = dataclasses.replace(self._config, observation_q_rad=tuple(self._watch.observation_q_rad))
        move = ObservationMove(self._kin, config)
        self._drive(goal_handle, move)
        if not move.outcome.success and not move.outcome.canceled:
            reason = move.outcome.failure_reason
            move.outcome.failure_reason = f"not planning with the arm in the camera's view: {reason}"
        return move.outcome

    def _reachable_alternative(self, grasp, sequence: PickPlaceSequence, place, p: dict):
        """(grasp, sequence) to run: the planned best grasp, unless the sequence would refuse it before the arm
        moves (near the base its straight lift can run out of reach); then the first of the service's
        plan_grasp_alternatives ranked grasps that can be made. If none can, the best one (its refusal is the
        goal's result, as without alternatives)."""
        with self._lock:
            q_now = self._last_state[0].q_rad if self._last_state is not None else None
        reason = "" if q_now is None else sequence.plan_failure(q_now)
        if not reason:
            return grasp, sequence
        count = int(p["plan_grasp_alternatives"])
        self.get_logger().info(f"best grasp would be refused ({reason}); asking for {count} ranked grasps")
        for rank, candidate in enumerate(self._planned_grasps(count), start=1):
            try:
                other = self._sequence_for(candidate, place, p, sequence.squeeze_request)
            except (GoalError, ValueError):
                continue
            if not other.plan_failure(q_now):
                self.get_logger().info(f"picking ranked grasp {rank} of {count} instead")
                return candidate, other
        return grasp, sequence

    def _sequence_for(self, grasp, place, p: dict, squeeze: SqueezeRequest | None = None) -> PickPlaceSequence:
        return PickPlaceSequence(self._kin, self._config,
                                 grasp_target(grasp, p["base_frame"], p["default_youngs_modulus_pa"]), place, squeeze)

    @staticmethod
    def _squeeze_for(request, p: dict) -> SqueezeRequest | None:
        """The goal's squeeze (measure_stiffness, measure_only), or None."""
        if not (request.measure_stiffness or request.measure_only):
            return None
        hand = None
        if p["squeeze_hand_stiffness_npm"] > 0:    # 0: not calibrated (nothing taken out)
            hand = HandCalibration(float(p["squeeze_hand_stiffness_npm"]),
                                   float(p["squeeze_hand_compliance_sd_mpn"]), str(p["squeeze_hand_calibration"]))
        return SqueezeRequest(only=bool(request.measure_only),
                              width_resolution_m=float(p["squeeze_width_resolution_m"]),
                              settle_s=float(p["squeeze_settle_s"]), speed_mps=float(p["squeeze_speed_mps"]),
                              hand=hand)

    def _wait_for_servers(self, timeout_s: float):
        for client, name in ((self._arm_client, "arm_trajectory_action"), (self._move_client, "gripper_move_action"),
                             (self._grasp_client, "gripper_grasp_action")):
            if not client.wait_for_server(timeout_sec=timeout_s):
                raise GoalError(f"action server {self.resolve_topic_name(self._params()[name])} is not available")
