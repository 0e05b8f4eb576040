"""Helpers shared by the executor node tests (in-test driver and real fake driver)."""


def send_goal(ex, spin, client, goal, feedback=None, timeout_s: float = 10.0):
    """Send a PickAndPlace goal and spin until the server answered it; returns the goal handle."""
    if not getattr(client, "discovered", False):  # once: readiness checks later raced with the executor
        spin(ex, client.server_is_ready, 20.0, "the pick-and-place action server (discovery)")
        client.discovered = True
    return spin(ex, client.send_goal_async(goal, feedback_callback=feedback), timeout_s, "goal response")


def stop_driver_processes(processes) -> None:
    """Stop drivers started in their own context/executor thread: (context, executor, node, thread)."""
    for context, own, driver, thread in processes:
        own.shutdown(timeout_sec=2.0)
        driver.destroy_node()
        context.try_shutdown()
        thread.join(timeout=5.0)
