"""Read a running node's parameters (for the session metadata) through its parameter services."""
from concurrent.futures import ThreadPoolExecutor

from rcl_interfaces.srv import GetParameters, ListParameters
from rclpy.parameter import parameter_value_to_python

from defgg_ros.ros.cell_client import CellCallError, wait_future

# The cell's nodes whose parameters a session records.
CELL_NODES = ("segmentation_node", "grasp_inference_node", "executor_node", "fake_panda_driver")
# Those whose parameters decide a replayed grasp: a replay runs them with the recorded values.
PERCEPTION_NODES = ("segmentation_node", "grasp_inference_node")


def fetch_parameters(node, node_name: str, timeout_s: float = 3.0) -> dict | None:
    """{name: value} of `/node_name`, or None when the node is not running (within timeout_s)."""
    list_client = node.create_client(ListParameters, f"/{node_name}/list_parameters")
    get_client = node.create_client(GetParameters, f"/{node_name}/get_parameters")
    try:
        if not (list_client.wait_for_service(timeout_sec=timeout_s) and get_client.wait_for_service(timeout_sec=1.0)):
            return None
        names = wait_future(list_client.call_async(ListParameters.Request()), timeout_s,
                            f"{node_name} list_parameters").result.names
        values = wait_future(get_client.call_async(GetParameters.Request(names=list(names))), timeout_s,
                             f"{node_name} get_parameters").values
        return {name: _plain(parameter_value_to_python(v)) for name, v in zip(names, values)}
    except CellCallError:
        return None
    finally:
        node.destroy_client(list_client)
        node.destroy_client(get_client)


def fetch_all(node, node_names=CELL_NODES, timeout_s: float = 3.0) -> dict:
    """{node: parameters} of those of `node_names` that answer; asked in parallel (absent ones cost one timeout)."""
    with ThreadPoolExecutor(max_workers=len(node_names)) as pool:
        results = pool.map(lambda name: (name, fetch_parameters(node, name, timeout_s)), node_names)
        return {name: params for name, params in results if params is not None}


def _plain(value):
    """JSON-friendly: arrays become lists."""
    return list(value) if not isinstance(value, (str, bytes, bool, int, float, type(None))) else value
