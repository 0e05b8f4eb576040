"""The training loop: deterministic, resumable, optionally distributed (DDP).

Determinism: the network is initialised from `seed`; each epoch's order is a
permutation drawn from (seed, epoch); each item's augmentation from (seed,
epoch, index) (GraspDataset). Nothing else is random, so a run resumed from
`state.pt` continues exactly where the killed one stopped and ends with the
same weights as an uninterrupted run.

Distributed: under `torchrun` (WORLD_SIZE > 1) every rank trains on its
share of each epoch's permutation (gloo, CPU) and DDP averages gradients;
rank 0 alone validates and writes files. The global batch is
batch_size x world size.
"""
from __future__ import annotations

import json
import os
import time
from pathlib import Path

import torch
import torch.distributed as dist
from tqdm import tqdm

from defgg_ros.atomic import atomic_path, write_json_atomic
from defgg_ros.constants import TRAINING_YOUNGS_MODULI_PA
from defgg_ros.data.dataset import GraspDataset, build_manifest, manifest_fingerprint
from defgg_ros.data.format import DatasetError, check_header, read_scene
from defgg_ros.data.header import label_grip_rule, recorded_protocol
from defgg_ros.model.checkpoint import load_checkpoint, network_from_checkpoint, save_checkpoint
from defgg_ros.model.network import GGCNN
from defgg_ros.train.config import TrainConfig
from defgg_ros.train.metrics import dataset_loss, grasp_loss, rectangle_accuracy, stiffness_response
from defgg_ros.train.plots import plot_curves, plot_stiffness_response
from defgg_ros.train.split import fixed_split, split_objects, split_scenes

STATE_FORMAT = "defgg-train-state"
STATE_FILE, MODEL_FILE, BEST_FILE = "state.pt", "model.pt", "best.pt"
METRICS_FILE, CURVES_FILE, RESPONSE_FILE = "metrics.json", "curves.png", "stiffness_response.png"
# Hyper-parameters that may change on --resume (they do not alter what has been computed).
RESUMABLE_OVERRIDES = ("epochs", "max_steps")


def labelled_scene_objects(data_root: Path, manifest: dict) -> dict:
    """{scene id: object name} of the scenes whose object has a trial in the manifest. An object without any
    (the sampler found no candidate for it) has no label anywhere: were it split, a validation or test slot
    would hold an object with nothing to score (fem_v5: 5 of 30 objects)."""
    objects = {sid: read_scene(data_root / "scenes" / f"{sid}.npz").object_name for sid in manifest}
    labelled = {name for sid, name in objects.items() if manifest[sid] > 0}
    return {sid: name for sid, name in objects.items() if name in labelled}


class TrainingError(RuntimeError):
    """Training cannot start or resume (bad data, mismatched state)."""


def distributed_context() -> tuple:
    """(rank, world_size); initialises gloo when started by torchrun."""
    world = int(os.environ.get("WORLD_SIZE", "1"))
    if world > 1 and not dist.is_initialized():
        dist.init_process_group("gloo")
    return (dist.get_rank(), world) if world > 1 else (0, 1)


def epoch_batches(n_items: int, batch_size: int, seed: int, epoch: int, rank: int, world: int) -> list:
    """This rank's batches (lists of item indices) for one epoch.

    Every rank gets the same number of batches (DDP needs equal step counts),
    so up to world-1 items of the permutation are dropped per epoch.
    """
    perm = torch.randperm(n_items, generator=torch.Generator().manual_seed(seed * 100_003 + epoch)).tolist()
    per_rank = n_items // world
    shard = perm[rank::world][:per_rank]
    return [shard[i:i + batch_size] for i in range(0, len(shard), batch_size)]


def _collate(items: list) -> dict:
    return {"x": torch.stack([it["x"] for it in items]), "y": torch.stack([it["y"] for it in items])}


class Trainer:
    def __init__(self, config: TrainConfig, data_root, out_dir, resume: bool = False, workers: int = 0,
                 checkpoint_every_steps: int = 0, show_progress: bool = True):
        self.data_root, self.out = Path(data_root), Path(out_dir)
        self.rank, self.world = distributed_context()
        self.workers, self.checkpoint_every = workers, checkpoint_every_steps
        self.show_progress = show_progress and self.rank == 0
        state = self._load_state(config) if resume and (self.out / STATE_FILE).exists() else None
        self.config = TrainConfig.from_dict(state["config"]) if state else config
        if state:
            for key in RESUMABLE_OVERRIDES:
                setattr(self.config, key, getattr(config, key))
        self._prepare_data(state)
        torch.manual_seed(self.config.seed)
        self.model = GGCNN(self.config.network_config())
        self.optimizer = torch.optim.Adam(self.model.parameters(), lr=self.config.learning_rate)
        self.epoch, self.batch, self.global_step, self.history = 0, 0, 0, []
        self.running = {"loss_sum": 0.0, "images": 0, "seconds": 0.0}
        if state:
            self._restore(state)
        self.ddp = torch.nn.parallel.DistributedDataParallel(self.model) if self.world > 1 else None

    # ----- data -----------------------------------------------------------
    def _prepare_data(self, state) -> None:
        if state:
            self.manifest, self.object_split = state["manifest"], state["object_split"]
            self.fingerprint = manifest_fingerprint(self.data_root, self.manifest)
            if self.fingerprint != state["data_fingerprint"]:
                raise TrainingError(f"{self.data_root}: data of the run changed since it started "
                                    f"({self.fingerprint} != {state['data_fingerprint']}); cannot resume")
        else:
            self.manifest = build_manifest(self.data_root)
            if not self.manifest:
                raise TrainingError(f"{self.data_root}: no scenes yet")
            self.fingerprint = manifest_fingerprint(self.data_root, self.manifest)
        # recorded in every checkpoint: the trial protocol of the labels, and the force the cell grasps with
        generator = check_header(self.data_root).get("generator") or {}
        self.label_grip_rule = label_grip_rule(generator)
        protocol = recorded_protocol(generator)
        self.trial_protocol = protocol.to_setting()
        if self.rank == 0:
            print(f"defgg-train: labels of the trial protocol {protocol.summary()}", flush=True)
        scene_objects = labelled_scene_objects(self.data_root, self.manifest)
        if not state and self.config.val_objects:
            self.object_split = fixed_split(scene_objects.values(), self.config.val_objects, self.config.test_objects)
        elif not state:
            self.object_split = split_objects(scene_objects.values(), self.config.val_fraction,
                                              self.config.test_fraction, self.config.object_split_seed)
        self.scene_split = split_scenes(scene_objects, self.object_split)
        c = self.config
        common = {"manifest": self.manifest, "uses_stiffness": c.uses_stiffness, "label_rule": c.label_rule,
                  "max_height_offset_m": c.max_height_offset_m}
        self.train_set = GraspDataset(self.data_root, self.scene_split["train"], augment=c.augment,
                                      samples_per_scene=c.samples_per_scene, seed=c.seed, **common)
        self.val_set = GraspDataset(self.data_root, self.scene_split["val"], **common)
        self.test_set = GraspDataset(self.data_root, self.scene_split["test"], **common)
        if len(self.train_set) == 0 or len(self.val_set) == 0:
            raise TrainingError(f"{self.data_root}: the train or validation split has no scene with a positive "
                                f"grasp yet (train {len(self.train_set)}, val {len(self.val_set)} items)")

    # ----- state ----------------------------------------------------------
    def _load_state(self, config: TrainConfig) -> dict:
        path = self.out / STATE_FILE
        try:
            state = torch.load(path, map_location="cpu", weights_only=True)
        except Exception as exc:
            raise TrainingError(f"{path}: cannot read training state ({type(exc).__name__}: {exc})") from None
        if not isinstance(state, dict) or state.get("format") != STATE_FORMAT:
            raise TrainingError(f"{path}: not a {STATE_FORMAT} file")
        if Path(state["data_root"]).resolve() != self.data_root.resolve():
            raise TrainingError(f"{path}: run used data {state['data_root']}, not {self.data_root}")
        saved, given = dict(state["config"]), config.to_dict()
        for key in RESUMABLE_OVERRIDES:
            saved.pop(key), given.pop(key)
        if saved != given:
            diff = sorted(k for k in saved if saved[k] != given.get(k))
            raise TrainingError(f"{path}: hyper-parameters differ from the run being resumed: {diff}")
        return state

    def _restore(self, state: dict) -> None:
        started_with = state.get("world")         # None: a state before 2026-12-01 (not recorded: not checked)
        if started_with is not None and started_with != self.world:   # another shard layout and global batch
            raise TrainingError(f"{self.out}: the run was started with {started_with} process(es), this is "
                                f"{self.world}; resume it with the same number (torchrun --nproc_per_node)")
        self.model.load_state_dict(state["model"])
        self.optimizer.load_state_dict(state["optimizer"])
        self.epoch, self.batch, self.global_step = state["epoch"], state["batch"], state["global_step"]
        self.history, self.running = state["history"], state["running"]

    def _save_state(self) -> None:
        if self.rank != 0:
            return
        state = {"format": STATE_FORMAT, "config": self.config.to_dict(), "data_root": str(self.data_root),
                 "manifest": self.manifest, "data_fingerprint": self.fingerprint,
                 "object_split": self.object_split, "epoch": self.epoch, "batch": self.batch,
                 "global_step": self.global_step, "history": self.history, "running": self.running,
                 "world": self.world,
                 "model": self.model.state_dict(), "optimizer": self.optimizer.state_dict()}
        with atomic_path(self.out / STATE_FILE) as tmp:
            torch.save(state, tmp)

    # ----- loop -----------------------------------------------------------
    def run(self) -> dict:
        self.out.mkdir(parents=True, exist_ok=True)
        while self.epoch < self.config.epochs and not self._step_limit_reached():
            if self._train_epoch():
                self._end_epoch()
            else:   # --max-steps stopped it mid-epoch: a resume goes on with the epoch's next batch
                self._end_partial_epoch()
        return self._finish()

    def _step_limit_reached(self) -> bool:
        return self.config.max_steps is not None and self.global_step >= self.config.max_steps

    def _train_epoch(self) -> bool:
        """Train on the epoch's remaining batches; False when the step limit stopped it before the last."""
        c = self.config
        self.train_set.set_epoch(self.epoch)
        batches = epoch_batches(len(self.train_set), c.batch_size, c.seed, self.epoch, self.rank, self.world)
        loader = torch.utils.data.DataLoader(self.train_set, batch_sampler=batches[self.batch:],
                                             num_workers=self.workers, collate_fn=_collate)
        model = self.ddp or self.model
        model.train()
        bar = tqdm(loader, total=len(batches), initial=self.batch, desc=f"epoch {self.epoch + 1}/{c.epochs}",
                   unit="batch", disable=not self.show_progress, dynamic_ncols=True)
        for batch in bar:
            t0 = time.perf_counter()
            loss = grasp_loss(model(batch["x"]), batch["y"], self.config.positive_weight)["loss"]
            self.optimizer.zero_grad(set_to_none=True)
            loss.backward()
            self.optimizer.step()
            self.running["seconds"] += time.perf_counter() - t0
            self.running["loss_sum"] += float(loss.detach()) * len(batch["x"])
            self.running["images"] += len(batch["x"])
            self.batch += 1
            self.global_step += 1
            bar.set_postfix(loss=f"{float(loss.detach()):.4f}")
            if self.checkpoint_every and self.global_step % self.checkpoint_every == 0:
                self._save_state()
            if self._step_limit_reached():
                break
        bar.close()
        return self.batch >= len(batches)

    def _reduced_running(self) -> dict:
        if self.world == 1:
            return dict(self.running)
        t = torch.tensor([self.running["loss_sum"], self.running["images"], self.running["seconds"]],
                         dtype=torch.float64)
        dist.all_reduce(t)
        return {"loss_sum": float(t[0]), "images": int(t[1]), "seconds": float(t[2]) / self.world}

    def _end_epoch(self) -> None:
        running = self._reduced_running()
        self.epoch, self.batch = self.epoch + 1, 0
        self.running = {"loss_sum": 0.0, "images": 0, "seconds": 0.0}
        self._record_validation(running, self.epoch)

    def _end_partial_epoch(self) -> None:
        """Validate and write the outputs of a run stopped mid-epoch, keeping epoch, batch and the running
        sums, so that a resume finishes the same epoch (its record then replaces this partial one)."""
        self._record_validation(self._reduced_running(), self.epoch + 1, partial=True)

    def _record_validation(self, running: dict, epoch: int, partial: bool = False) -> None:
        self.history = [h for h in self.history if not (h.get("partial") and h["epoch"] == epoch)]
        if self.rank == 0:
            val = rectangle_accuracy(self.model, self.val_set.samples, self.config.uses_stiffness)
            self.history.append({
                "epoch": epoch, "step": self.global_step, **({"partial": True} if partial else {}),
                "train_loss": running["loss_sum"] / max(running["images"], 1), "train_images": running["images"],
                "train_images_per_s": running["images"] / max(running["seconds"], 1e-9),
                "val_loss": dataset_loss(self.model, self.val_set, positive_weight=self.config.positive_weight),
                "val_accuracy": val["accuracy"],
                "val_per_modulus": val["per_modulus"]})
            self._write_epoch_outputs()
            if not self.show_progress:   # a log (nohup, models/retrain_pair.sh) still shows how far the run is
                h = self.history[-1]
                stopped = " (stopped in it)" if partial else ""
                print(f"defgg-train: epoch {h['epoch']}/{self.config.epochs}{stopped}: "
                      f"train loss {h['train_loss']:.4f}, val loss {h['val_loss']:.4f}, "
                      f"val accuracy {h['val_accuracy']:.2f}, {h['train_images_per_s']:.1f} images/s", flush=True)
        self._save_state()
        if self.world > 1:
            dist.barrier()

    def _checkpoint_meta(self, record: dict) -> dict:
        return {"epoch": record["epoch"], "val_accuracy": record["val_accuracy"], "val_loss": record["val_loss"],
                "val_per_modulus": record["val_per_modulus"], "train_config": self.config.to_dict(),
                "object_split": self.object_split, "data_root": str(self.data_root),
                "n_trials": int(sum(self.manifest.values())), "label_grip_rule": self.label_grip_rule,
                "trial_protocol": self.trial_protocol}

    def _best_record(self) -> dict:
        """The best validation over whole epochs; a partial epoch's (a --max-steps stop) only while there is none."""
        whole = [h for h in self.history if not h.get("partial")] or self.history
        return max(whole, key=lambda h: (h["val_accuracy"], -h["val_loss"]))

    def _write_epoch_outputs(self) -> None:
        record = self.history[-1]
        save_checkpoint(self.out / MODEL_FILE, self.model, self.fingerprint, self._checkpoint_meta(record))
        if self._best_record() is record:
            save_checkpoint(self.out / BEST_FILE, self.model, self.fingerprint, self._checkpoint_meta(record))
        plot_curves(self.history, self.out / CURVES_FILE)
        self._write_metrics()

    def _write_metrics(self, extra: dict | None = None) -> dict:
        metrics = {"config": self.config.to_dict(), "world_size": self.world,
                   "data": {"root": str(self.data_root), "fingerprint": self.fingerprint,
                            "trial_protocol": self.trial_protocol,
                            "n_trials": int(sum(self.manifest.values())), "object_split": self.object_split,
                            "scenes": {k: len(v) for k, v in self.scene_split.items()},
                            "scenes_without_positive": {"train": self.train_set.skipped_scene_ids,
                                                        "val": self.val_set.skipped_scene_ids,
                                                        "test": self.test_set.skipped_scene_ids}},
                   "history": self.history, **(extra or {})}
        write_json_atomic(self.out / METRICS_FILE, metrics)
        return metrics

    def _finish(self) -> dict:
        if self.rank != 0 or not self.history:
            return {}
        best_model = network_from_checkpoint(load_checkpoint(self.out / BEST_FILE))
        best_epoch = self._best_record()["epoch"]
        test = rectangle_accuracy(best_model, self.test_set.samples, self.config.uses_stiffness) \
            if self.test_set.samples else None
        response = stiffness_response(best_model, self.val_set.samples, TRAINING_YOUNGS_MODULI_PA)
        plot_stiffness_response(best_model, self.val_set.samples[0], TRAINING_YOUNGS_MODULI_PA, response,
                                self.out / RESPONSE_FILE)
        return self._write_metrics({"best_epoch": best_epoch, "test": test, "stiffness_response": response})


def train(config: TrainConfig, data_root, out_dir, **kwargs) -> dict:
    """Train (or resume with resume=True) and return the final metrics dict."""
    try:
        return Trainer(config, data_root, out_dir, **kwargs).run()
    except DatasetError as exc:
        raise TrainingError(str(exc)) from None
    finally:
        if dist.is_initialized():
            dist.destroy_process_group()


def load_metrics(out_dir) -> dict:
    return json.loads((Path(out_dir) / METRICS_FILE).read_text())
