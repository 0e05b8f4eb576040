"""Which nodes a replay starts, with which parameters, and which model it runs.

The replay runs the *current* code and shipped model on the recorded
inputs; recorded node parameters that shape the result (camera extrinsic,
segmentation thresholds, the grasp service's post-processing steps, the executor's grasp height
and guarded-descent settings) are applied so a session recorded with non-default settings still
replays like it was recorded.
"""
from dataclasses import dataclass
from pathlib import Path

from defgg_ros.ros.share import share_path
from defgg_ros.sessions import metadata as md
from defgg_ros.sessions.replay_nodes import NodeSpec
from defgg_ros.sessions.session_topics import topics  # absolute names (bag channels)

MODELS_DIR = share_path("models")
# Recorded parameters re-applied in the replay (topic names are not: the player uses the defaults).
REPLAYED_PARAMETERS = {
    # The only perceiver: the camera extrinsic, the frames and what decides which pixels are objects.
    "segmentation_node": ("base_T_camera", "base_frame", "default_youngs_modulus_pa", "min_object_height_m"),
    "grasp_inference_node": (),
    # Those that decide where and how a replayed pick grasps (a changed default must not change a replay).
    "executor_node": ("table_z_m", "pregrasp_height_m", "grasp_depth_below_surface_m", "grasp_height_rule",
                      "descent_speed_mps", "contact_force_threshold_n", "lift_height_m", "slip_width_fraction",
                      "default_youngs_modulus_pa"),
}
# What a recording made before a parameter existed did (recorded parameter sets lack the name).
BEFORE_PARAMETER_EXISTED = {
    "executor_node": {"grasp_height_rule": "below_surface"},
}
# The fake driver renders its own camera; in a replay the recorded frames are the camera.
DRIVER_CAMERA_REMAPS = {
    topics.DEPTH_IMAGE: "/defgg_replay/unused/depth",
    topics.DEPTH_CAMERA_INFO: "/defgg_replay/unused/depth_camera_info",
    topics.COLOR_IMAGE: "/defgg_replay/unused/color",
    topics.COLOR_CAMERA_INFO: "/defgg_replay/unused/color_camera_info",
}


# Its renders are unused (remapped away): render rarely. It keeps its deployed real-time pace: run
# unthrottled on a loaded machine it starved the executor's wall-clock loop (picks aborted at pre_grasp).
DRIVER_REPLAY_PARAMETERS = {"depth_rate_hz": 0.2, "publish_color": False}


@dataclass(frozen=True)
class ModelChoice:
    path: Path
    use_stiffness: bool
    sha256: str

    def change_from(self, metadata: dict) -> str:
        """'' when this is the recorded model, else what changed (for the regression message)."""
        recorded = metadata.get("model") or {}
        if recorded.get("sha256") == self.sha256:
            return ""
        return (f"the model differs from the recording: {self.path.name} sha256 {self.sha256[:12]}, "
                f"recorded {recorded.get('file', '?')} sha256 {recorded.get('sha256', '?')[:12]}")

    def describe(self, metadata: dict) -> str:
        recorded = (metadata.get("model") or {}).get("sha256", "")
        same = "same as recorded" if recorded == self.sha256 else f"CHANGED, recorded {recorded[:12] or '?'}"
        return (f"model {self.path.name} ({'depth+stiffness' if self.use_stiffness else 'depth only'}, "
                f"sha256 {self.sha256[:12]}, {same})")


def _checkpoint_uses_stiffness(path: Path) -> bool:
    from defgg_ros.model.checkpoint import load_checkpoint  # torch (~1.2 CPU-s): only for a model given explicitly

    return int(load_checkpoint(path)["network_config"]["input_channels"]) == 2


def resolve_model(metadata: dict, model_arg: str | None, use_stiffness_arg: str | None) -> ModelChoice:
    """--model/--use-stiffness, else the shipped file the session names (models/<file>)."""
    recorded = metadata.get("model") or {}
    if model_arg:
        path = Path(model_arg)
        if not path.is_file():
            raise md.MetadataError(f"--model {path} does not exist")
        use_stiffness = _checkpoint_uses_stiffness(path) if use_stiffness_arg is None else use_stiffness_arg == "true"
    else:
        if not recorded.get("file"):
            raise md.MetadataError("the session names no model file; pass --model")
        path = MODELS_DIR / recorded["file"]
        if not path.is_file():
            raise md.MetadataError(f"the session's model {recorded['file']} is not in {MODELS_DIR}; pass --model")
        use_stiffness = bool(recorded.get("use_stiffness", True)) if use_stiffness_arg is None \
            else use_stiffness_arg == "true"
    return ModelChoice(path, use_stiffness, md.file_sha256(path))


def _recorded(metadata: dict, node: str) -> dict:
    """The node's recorded parameters that a replay re-applies ({} when none were recorded)."""
    values = (metadata.get("parameters") or {}).get(node) or {}
    if values:
        values = {**BEFORE_PARAMETER_EXISTED.get(node, {}), **values}
    return {k: values[k] for k in REPLAYED_PARAMETERS.get(node, ()) if k in values}


def graph_specs(metadata: dict, model: ModelChoice, pick: bool, run_dir: Path) -> list[NodeSpec]:
    specs = [
        NodeSpec("segmentation_node", "defgg_ros.nodes.segmentation_node", _recorded(metadata, "segmentation_node")),
        NodeSpec("grasp_inference_node", "defgg_ros.nodes.grasp_inference_node",
                 {**_recorded(metadata, "grasp_inference_node"), "model_path": str(model.path.resolve()),
                  "use_stiffness": model.use_stiffness, "publish_on_sync": True, "num_threads": 1}),
    ]
    if pick:
        scene_file = Path(run_dir) / "scene.yaml"
        scene_file.write_text(md.scene_yaml(metadata), encoding="utf-8")
        specs += [
            NodeSpec("fake_panda_driver", "defgg_ros.nodes.fake_panda_driver_node",
                     {"scene_file": str(scene_file), **DRIVER_REPLAY_PARAMETERS}, dict(DRIVER_CAMERA_REMAPS)),
            NodeSpec("executor_node", "defgg_ros.nodes.executor_node",
                     {**_recorded(metadata, "executor_node"), "use_sim_time": True}),
        ]
    return specs
