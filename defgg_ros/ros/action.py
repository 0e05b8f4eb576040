"""An rclpy ActionClient whose requests cannot lose their responses.

rclpy 7.1.6 (the Jazzy wheels this project installs) sends a goal, cancel or result request and
only afterwards records its sequence number. When the server answers before that line runs, an
executor thread takes the response, finds no pending request ("Ignoring unexpected goal response.
There may be more than one action server") and the caller's future never completes: a pick that
waits forever for the gripper, a replay that gets "no answer within 10 s". On an idle 2-core VM
the answer is often that fast; a busy machine hides it. This is ros2/rclpy#1123, fixed upstream
by holding a lock across send + record and across take (ros2/rclpy#1308, backported to Jazzy
after 7.1.6). This subclass does the same, so every node and tool here is correct on the wheels
it installs and stays correct once they carry the fix.
"""
import threading

from rclpy.action import ActionClient as _RclpyActionClient

from defgg_ros.ros.service import first_answer

# How often a goal's result is asked for again while it has not come: a long goal (a pick on a loaded machine:
# 10 min) outlives any discovery hiccup, so this only has to beat the server's result_timeout (rclpy: 900 s).
RESULT_RESEND_EVERY_S = 30.0


class ResultTimeout(TimeoutError):
    """No result for a goal within the deadline, however often it was asked for."""


class ActionClient(_RclpyActionClient):
    """rclpy's ActionClient with request sending and response taking serialised by one lock."""

    def __init__(self, *args, **kwargs):
        # Before super(): the base constructor registers the waitable, after which an executor
        # thread may call take_data() at any time.
        self._request_lock = threading.Lock()
        super().__init__(*args, **kwargs)

    def take_data(self):
        with self._request_lock:
            return super().take_data()

    def send_goal_async(self, goal, feedback_callback=None, goal_uuid=None):
        with self._request_lock:
            return super().send_goal_async(goal, feedback_callback=feedback_callback, goal_uuid=goal_uuid)

    def _cancel_goal_async(self, goal_handle):
        with self._request_lock:
            return super()._cancel_goal_async(goal_handle)

    def _get_result_async(self, goal_handle):
        with self._request_lock:
            return super()._get_result_async(goal_handle)


def result_of_goal(handle, timeout_s: float, what: str, wait_until, resend_every_s: float = RESULT_RESEND_EVERY_S):
    """The result (GetResult response: .status, .result) of an accepted goal, asking for it again every
    `resend_every_s` until one answer arrives or `timeout_s` passes (ResultTimeout).

    A result request is a service call: its response can be lost like any other (defgg_ros.ros.service: Fast
    DDS drops a response it cannot deliver within 100 ms). The cell experiment saw it twice in ~330 picks on a
    loaded machine: the executor logged "pick-and-place done" (601 s, 77 s after the goal), the client had no
    result at 1,800 s. Asking again is safe: the server answers every request for a goal (at once if it is
    done) and keeps a finished goal's result for its result_timeout. `wait_until(predicate, timeout_s) -> bool`
    waits (and spins, for a caller that spins its own node)."""
    return first_answer(handle.get_result_async, timeout_s, what, resend_every_s, wait_until,
                        lambda sends: ResultTimeout(f"timed out after {timeout_s:g} s waiting for {what} "
                                                    f"({sends} requests)"))


def in_executor(node, callback):
    """A done-callback that hands `callback(future)` to the node's executor as a task.

    rclpy runs a done-callback at once, in the thread that attaches it, when the future is already done: an
    answer that arrives between send_goal_async and add_done_callback would run the callback inside a caller
    that holds a lock the callback takes (the executor sends goals with its lock held), a deadlock. As a task it
    runs after the caller has let go. With no executor (a node spun by hand) it runs at once."""
    def schedule(future):
        executor = node.executor
        if executor is None:
            callback(future)
        else:
            executor.create_task(callback, future)
    return schedule


def destroy_actions(node) -> None:
    """Destroy every action server and client of `node`.

    rclpy 7.1's Node.destroy_node destroys publishers, subscriptions, services and timers but not
    waitables: a destroyed node's actions stay advertised (and keep its DDS participant busy) until the
    garbage collector gets to them. A driver that was shut down must not look alive to the executor's
    discovery, so every node here that owns actions calls this from its destroy_node.
    """
    from rclpy.action import ActionServer as _RclpyActionServer

    for waitable in list(node.waitables):
        if isinstance(waitable, (_RclpyActionServer, _RclpyActionClient)):
            waitable.destroy()
