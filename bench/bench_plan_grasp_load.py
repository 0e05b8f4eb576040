"""PlanGrasp under load: many calls from several client nodes, nothing dropped, memory flat.

Starts segmentation_node and grasp_inference_node in their own processes (private ROS_DOMAIN_ID), primes
it with one synchronised frame, then `--clients` client nodes each keep
`--in-flight` requests outstanding until `--calls` calls are answered in total
(a `--image-fraction` of them carry depth + camera_info, perceived through Perceive, the rest
are empty "latest frame" requests). Repeats for `--rounds` rounds and prints,
per round: answered / dropped (no answer within --timeout) / failed
(success=false), throughput, latency median and p99, and the node's resident
memory (VmRSS) before and after.
"""
import argparse
import os
import random
import threading
import time

import numpy as np
from bench_plan_grasp import (
    Cell,
    make_executor,
    messages,
    prime_latest_frame,
    rss_mb,
    scene,
    start_node,
    wait_for_node,
)

from defgg_ros.nodes.grasp_inference_node import default_model_path
from defgg_ros.ros.domain import pick_private_domain
from defgg_ros.ros.transport import use_large_message_transport


def parse_args(argv=None):
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--calls", type=int, default=1000, help="calls per round, over all clients")
    parser.add_argument("--clients", type=int, default=4, help="client nodes")
    parser.add_argument("--in-flight", type=int, default=2, help="outstanding requests per client")
    parser.add_argument("--image-fraction", type=float, default=0.2, help="share of requests carrying images")
    parser.add_argument("--rounds", type=int, default=2, help="rounds (RSS is printed after each)")
    parser.add_argument("--timeout", type=float, default=60.0, help="seconds a call may take before it counts "
                                                                    "as dropped")
    parser.add_argument("--model", default=str(default_model_path(True)), help="checkpoint")
    parser.add_argument("--threads", type=int, default=1, help="torch threads in the node")
    parser.add_argument("--client-executor", choices=("events", "single"), default="events",
                        help="executor spinning the client nodes")
    return parser.parse_args(argv)


class LoadRound:
    """Keeps every client's pipeline full until `total` calls have been sent."""

    def __init__(self, clients, requests, total, in_flight, rng):
        self.clients, self.requests, self.total, self.in_flight = clients, requests, total, in_flight
        self.rng = rng
        self.lock = threading.Lock()
        self.sent = 0
        self.latencies, self.failures, self.pending = [], [], {}

    def start(self):
        for client in self.clients:
            for _ in range(self.in_flight):
                self._send(client)

    def _send(self, client):
        with self.lock:
            if self.sent >= self.total:
                return
            self.sent += 1
            call_id = self.sent
        request = self.requests[0] if self.rng.random() >= self.requests[2] else self.requests[1]
        start = time.perf_counter()
        future = client.call_async(request)
        with self.lock:
            self.pending[call_id] = future
        future.add_done_callback(lambda f, c=client, i=call_id, t=start: self._done(f, c, i, t))

    def _done(self, future, client, call_id, start):
        response = future.result()
        with self.lock:
            self.pending.pop(call_id, None)
            self.latencies.append(time.perf_counter() - start)
            if not response.success:
                self.failures.append(response.message)
        self._send(client)

    def finished(self) -> bool:
        with self.lock:
            return self.sent >= self.total and not self.pending


def run_round(executor, clients, requests, args, rng):
    load = LoadRound(clients, requests, args.calls, args.in_flight, rng)
    start = time.perf_counter()
    load.start()
    deadline = time.monotonic() + args.timeout + args.calls * 1.0
    while not load.finished() and time.monotonic() < deadline:
        executor.spin_once(timeout_sec=0.1)
    return load, time.perf_counter() - start


def main(argv=None):
    args = parse_args(argv)
    os.environ["ROS_DOMAIN_ID"] = str(pick_private_domain())
    os.environ["ROS_AUTOMATIC_DISCOVERY_RANGE"] = "LOCALHOST"
    use_large_message_transport()  # the cell's Fast DDS transports, as defgg-bringup sets them
    import rclpy
    from defgg_interfaces.srv import PlanGrasp
    from rclpy.context import Context
    from tqdm import tqdm

    depth_m, moduli_pa, camera_k, base_T_camera = scene(640, 480)   # the generated cluttered table
    proc = start_node(args.model, args.threads, base_T_camera)
    context = Context()
    rclpy.init(context=context)
    try:
        primer = Cell(context, "bench_load_primer", args.client_executor)
        wait_for_node(primer, proc)
        frame_msgs = messages(depth_m, moduli_pa, camera_k)
        prime_latest_frame(primer, frame_msgs)
        image_request = PlanGrasp.Request(depth=frame_msgs[0], camera_info=frame_msgs[1])
        requests = (PlanGrasp.Request(), image_request, args.image_fraction)
        executor = make_executor(args.client_executor, context)
        clients = []
        for index in range(args.clients):
            node = rclpy.create_node(f"bench_load_client_{index}", context=context)
            executor.add_node(node)
            client = node.create_client(PlanGrasp, "/defgg/plan_grasp")
            if not client.wait_for_service(timeout_sec=30.0):
                raise RuntimeError("client never saw the service")
            clients.append(client)
        rss_start = rss_mb(proc.pid)
        print(f"node RSS before: {rss_start:.1f} MB")
        rng = random.Random(0)
        for round_index in tqdm(range(args.rounds), desc="rounds"):
            load, seconds = run_round(executor, clients, requests, args, rng)
            report(round_index, load, seconds, args, rss_mb(proc.pid))
    finally:
        proc.stop()
        context.try_shutdown()


def report(round_index, load, seconds, args, rss_after_mb):
    ms = np.asarray(load.latencies) * 1e3
    dropped = len(load.pending) + (args.calls - load.sent)
    print(f"round {round_index + 1}: {len(load.latencies)}/{args.calls} answered, {dropped} dropped, "
          f"{len(load.failures)} failed; {args.clients} clients x {args.in_flight} in flight; "
          f"{len(ms) / seconds:.1f} calls/s; latency median {np.median(ms):.1f} ms, p99 {np.percentile(ms, 99):.1f} ms;"
          f" node RSS after {rss_after_mb:.1f} MB; load average {os.getloadavg()[0]:.1f}")
    if load.failures:
        print(f"  first failure: {load.failures[0]}")


if __name__ == "__main__":
    main()
