"""A person's recovery after a robot error, as franka_hardware's doc gives it, from a test's client node over DDS:
`action_server/error_recovery`, the hardware component set active, the controllers activated (STRICT)."""
from controller_manager_msgs.srv import ListControllers, SetHardwareComponentState, SwitchController
from franka_msgs.action import ErrorRecovery
from lifecycle_msgs.msg import State

from defgg_ros.ros import topics
from defgg_ros.ros.action import ActionClient

TIMEOUT_S = 60.0


class RecoveryClient:
    def __init__(self, node, executor, spin, arm_controller: str = topics.robot_names()["arm_controller"]):
        self.executor, self.spin = executor, spin
        self.controllers = (topics.JOINT_STATE_BROADCASTER, topics.ROBOT_STATE_BROADCASTER, arm_controller)
        self.recovery = ActionClient(node, ErrorRecovery, topics.ERROR_RECOVERY_ACTION)
        self.list = node.create_client(ListControllers, topics.LIST_CONTROLLERS_SERVICE)
        self.switch = node.create_client(SwitchController, topics.SWITCH_CONTROLLER_SERVICE)
        self.hardware = node.create_client(SetHardwareComponentState, topics.SET_HARDWARE_STATE_SERVICE)
        for what, ready in (("error_recovery", self.recovery.server_is_ready),
                            ("list_controllers", self.list.service_is_ready),
                            ("switch_controller", self.switch.service_is_ready),
                            ("set_hardware_component_state", self.hardware.service_is_ready)):
            spin(executor, ready, TIMEOUT_S, what)

    def call(self, client, request):
        return self.spin(self.executor, client.call_async(request), TIMEOUT_S, f"{client.srv_name}'s answer")

    def controller_states(self) -> dict:
        return {c.name: c.state for c in self.call(self.list, ListControllers.Request()).controller}

    def clear_error(self) -> None:
        handle = self.spin(self.executor, self.recovery.send_goal_async(ErrorRecovery.Goal()), TIMEOUT_S,
                           "error_recovery's answer")
        self.spin(self.executor, handle.get_result_async(), TIMEOUT_S, "error recovery")

    def activate_hardware(self):
        return self.call(self.hardware, SetHardwareComponentState.Request(
            name=topics.FRANKA_HARDWARE_COMPONENT, target_state=State(id=State.PRIMARY_STATE_ACTIVE, label="active")))

    def activate_controllers(self):
        return self.call(self.switch, SwitchController.Request(activate_controllers=list(self.controllers),
                                                               strictness=SwitchController.Request.STRICT))

    def recover(self) -> None:
        """The three steps in order; AssertionError if a step is refused."""
        self.clear_error()
        assert self.activate_hardware().ok, "the hardware component did not become active"
        answer = self.activate_controllers()
        assert answer.ok, answer.message
