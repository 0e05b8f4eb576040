"""Service calls that survive a lost request or a lost response.

With Fast DDS (the Jazzy wheels' default RMW) a service sends its response only once the
client's response reader has been discovered, and waits for that at most 100 ms
(max_blocking_time); past that, rclpy logs "failed to send response (timeout)" and drops it.
`wait_for_service()` only tells that the client has discovered the server, not the reverse, so
on a loaded 2-core machine the first call after start-up can go unanswered for ever: CI saw a
replay's first SetStiffness get "no answer within 10 s" from a segmentation node that was up.
A request sent before the server's request reader is matched is lost the same way.

For requests that are idempotent (setting the stiffness table, planning on the latest frame),
sending the same request again is safe, so the client re-sends it every `resend_every_s` until
one answer arrives or the deadline passes.
"""
import threading
import time

RESEND_EVERY_S = 2.0


class ServiceTimeout(TimeoutError):
    """No answer to any of the sends within the deadline."""


def call_idempotent(client, request, timeout_s: float, what: str, resend_every_s: float = RESEND_EVERY_S,
                    wait_until=None):
    """Call `client` with `request`, re-sending it until an answer arrives; returns the response.

    By default an executor must spin the client's node in another thread. A caller that spins
    itself passes `wait_until(predicate, timeout_s) -> bool`, which spins until predicate() holds.
    Raises ServiceTimeout after `timeout_s`, RuntimeError with the server's exception if it failed.
    """
    answered = threading.Event()

    def send():
        future = client.call_async(request)
        future.add_done_callback(lambda _: answered.set())
        return future

    return first_answer(send, timeout_s, what, resend_every_s,
                        wait_until or (lambda _predicate, wait_s: answered.wait(wait_s)),
                        lambda sends: ServiceTimeout(f"{what}: no answer within {timeout_s:g} s ({sends} sends)"))


def first_answer(send, timeout_s: float, what: str, resend_every_s: float, wait_until, timeout_error):
    """The result of the first of the futures `send()` returns (called again every `resend_every_s`) to be done.

    `wait_until(predicate, timeout_s) -> bool` waits (spinning, for a caller that spins its own node); at the
    deadline raises `timeout_error(number of sends)`; RuntimeError with the server's exception if it failed.
    Unanswered sends are cancelled (dropped from the client's pending table)."""
    if resend_every_s <= 0:
        raise ValueError(f"resend_every_s must be > 0, got {resend_every_s}")
    futures = []
    deadline = time.monotonic() + timeout_s
    try:
        while True:
            futures.append(send())
            remaining_s = max(deadline - time.monotonic(), 0.0)
            if wait_until(lambda: any(f.done() for f in futures), min(resend_every_s, remaining_s)):
                break
            if time.monotonic() >= deadline:
                raise timeout_error(len(futures))
        done = next(f for f in futures if f.done())
        if done.exception() is not None:
            raise RuntimeError(f"{what}: {done.exception()!r}")
        return done.result()
    finally:
        for future in futures:
            if not future.done():
                future.cancel()


def answer(response, work, what: str, logger, note_error=None):
    """A service callback's answer: work() fills the response's own fields and returns its message, then
    success is true. A ValueError (a bad request, a frame that cannot be used) answers success false with its
    text (note_error(text), e.g. the node's diagnostics); any other exception is a bug, logged as an error and
    answered as "internal error: ..." (a service must answer, whatever broke)."""
    try:
        message = work()
    except ValueError as exc:
        response.success, response.message = False, str(exc) or type(exc).__name__
        if note_error is not None:
            note_error(f"{what}: {response.message}")
        return response
    except Exception as exc:  # noqa: BLE001 - a service must answer, whatever broke
        logger.error(f"{what} failed unexpectedly: {exc!r}")
        response.success, response.message = False, f"internal error: {exc!r}"
        return response
    response.success, response.message = True, message
    return response
