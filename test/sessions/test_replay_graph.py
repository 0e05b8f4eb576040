"""Which recorded parameters a replay re-applies to the nodes it starts."""
import copy
from pathlib import Path

from defgg_ros.sessions.replay_graph import REPLAYED_PARAMETERS, ModelChoice, graph_specs
from defgg_ros.sessions.session import load_session

SESSION = Path(__file__).resolve().parents[2] / "sim_bringup" / "sessions" / "soft_objects"
MODEL = ModelChoice(path=Path("models/defgg_cnn.pt"), use_stiffness=True, sha256="0" * 64)


def _metadata(executor_parameters: dict | None) -> dict:
    """The shipped soft_objects session's metadata with these recorded executor parameters."""
    metadata = copy.deepcopy(load_session(SESSION).metadata)
    metadata["parameters"].pop("executor_node", None)
    if executor_parameters is not None:
        metadata["parameters"]["executor_node"] = executor_parameters
    return metadata


def _executor_spec(metadata, tmp_path):
    specs = graph_specs(metadata, MODEL, pick=True, run_dir=tmp_path)
    return next(s for s in specs if s.name == "executor_node")


def test_replayed_parameter_names_are_parameters_of_their_nodes():
    from defgg_ros.nodes import executor_node, grasp_inference_node, segmentation_node

    nodes = {"executor_node": executor_node, "grasp_inference_node": grasp_inference_node,
             "segmentation_node": segmentation_node}
    for name, replayed in REPLAYED_PARAMETERS.items():
        assert set(replayed) <= set(nodes[name].PARAMETERS), name


def test_a_pick_replays_with_the_recorded_grasp_height_and_descent(tmp_path):
    recorded = {"grasp_height_rule": "half_height", "grasp_depth_below_surface_m": 0.01,
                "contact_force_threshold_n": 7.0, "action_name": "/elsewhere/pick"}
    parameters = _executor_spec(_metadata(recorded), tmp_path).parameters
    assert parameters["grasp_height_rule"] == "half_height"
    assert parameters["grasp_depth_below_surface_m"] == 0.01
    assert parameters["contact_force_threshold_n"] == 7.0
    assert "action_name" not in parameters  # topic and action names: the player uses the defaults
    assert parameters["use_sim_time"] is True


def test_a_recording_older_than_the_grasp_height_rule_replays_with_the_rule_of_its_time(tmp_path):
    parameters = _executor_spec(_metadata({"grasp_depth_below_surface_m": 0.018}), tmp_path).parameters
    assert parameters["grasp_height_rule"] == "below_surface"
    # Nothing recorded for the executor at all: the shipped YAML decides, nothing is made up.
    assert _executor_spec(_metadata(None), tmp_path).parameters == {"use_sim_time": True}
