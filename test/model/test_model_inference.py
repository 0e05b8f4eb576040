"""GraspPredictor on a random-init checkpoint: geometry, contract, errors."""
import numpy as np
import pytest

from defgg_ros.constants import CAMERA_FX_PX
from defgg_ros.model.checkpoint import CheckpointError, make_random_checkpoint
from defgg_ros.model.inference import GraspPredictor
from defgg_ros.model.preprocess import InvalidInputError
from defgg_ros.stiffness import InvalidYoungsModulus

K = np.array([[CAMERA_FX_PX, 0.0, 320.0], [0.0, CAMERA_FX_PX, 240.0], [0.0, 0.0, 1.0]])


@pytest.fixture(scope="module")
def predictors(tmp_path_factory):
    d = tmp_path_factory.mktemp("ckpt")
    return {s: GraspPredictor.from_checkpoint(make_random_checkpoint(d / f"{s}.pt", uses_stiffness=s, seed=5))
            for s in (True, False)}


def _cell_scene():
    depth = np.full((480, 640), 0.40, np.float32)
    mask = np.zeros((480, 640), np.int32)
    mask[200:260, 420:500] = 7
    depth[mask > 0] = 0.36
    moduli = np.where(mask > 0, 2e5, 0.0).astype(np.float32)
    return depth, moduli, mask


def test_prediction_contract(predictors):
    depth, moduli, mask = _cell_scene()
    p = predictors[True].predict(depth, moduli, K, mask, top_k=3)
    assert p.q.shape == p.angle_rad.shape == p.width_px.shape == (300, 300)
    assert p.crop_offset_px == (460 - 150, 230 - 150)
    assert 0.0 <= p.q.min() and p.q.max() <= 1.0
    assert np.all(np.abs(p.angle_rad) <= np.pi / 2)
    assert 1 <= len(p.candidates) <= 3
    assert [c.quality for c in p.candidates] == sorted((c.quality for c in p.candidates), reverse=True)
    for c in p.candidates:
        u, v = int(c.center_u_px), int(c.center_v_px)
        assert mask[v, u] == 7 and c.object_id == 7          # peaks restricted to the mask
        assert c.youngs_modulus_pa == 2e5
        assert c.depth_m == pytest.approx(0.36)
        assert c.width_m == pytest.approx(c.width_px * 0.36 / CAMERA_FX_PX)
        x, y, z = c.position_camera_m
        assert (x, y, z) == pytest.approx(((u - 320) * 0.36 / CAMERA_FX_PX, (v - 240) * 0.36 / CAMERA_FX_PX, 0.36))
        assert p.q[v - p.crop_offset_px[1], u - p.crop_offset_px[0]] == pytest.approx(c.quality)


def test_without_mask_crop_is_centred_and_object_id_is_minus_one(predictors):
    depth, moduli, _ = _cell_scene()
    p = predictors[False].predict(depth, moduli, K)
    assert p.crop_offset_px == (170, 90)
    assert p.best.object_id == -1


def test_metadata(predictors):
    assert predictors[True].uses_stiffness and not predictors[False].uses_stiffness
    assert len(predictors[True].fingerprint) == 16
    assert predictors[True].checkpoint_meta["data_fingerprint"] == "untrained"


def test_depth_only_model_ignores_stiffness(predictors):
    depth, moduli, mask = _cell_scene()
    a = predictors[False].predict(depth, moduli, K, mask)
    b = predictors[False].predict(depth, moduli * 1000, K, mask)
    assert np.array_equal(a.q, b.q)


def _bad_inputs():
    depth, moduli, mask = _cell_scene()
    nan_e, neg_e, bad_k = moduli.copy(), moduli.copy(), K.copy()
    nan_e[0, 0], neg_e[5, 5], bad_k[0, 2] = np.nan, -1.0, np.inf
    return {
        "mismatched sizes": (depth, moduli[:, :600], K, None, InvalidInputError),
        "all invalid depth": (np.zeros_like(depth), moduli, K, None, InvalidInputError),
        "NaN modulus": (depth, nan_e, K, None, InvalidYoungsModulus),
        "negative modulus": (depth, neg_e, K, None, InvalidYoungsModulus),
        "non-finite K": (depth, moduli, bad_k, None, InvalidInputError),
        "2x2 K": (depth, moduli, K[:2, :2], None, InvalidInputError),
        "too small": (depth[:200, :200], moduli[:200, :200], K, None, InvalidInputError),
        "3-D depth": (depth[None], moduli[None], K, None, InvalidInputError),
        "empty mask": (depth, moduli, K, np.zeros_like(mask), InvalidInputError),
        "mask size": (depth, moduli, K, mask[:100], InvalidInputError),
    }


@pytest.mark.parametrize("case", list(_bad_inputs()))
@pytest.mark.parametrize("uses_stiffness", [True, False])
def test_bad_input_raises_value_errors(predictors, case, uses_stiffness):
    depth, moduli, k, mask, error = _bad_inputs()[case]
    with pytest.raises(error) as info:
        predictors[uses_stiffness].predict(depth, moduli, k, mask)
    assert isinstance(info.value, ValueError) and str(info.value)


def test_bad_checkpoint_path_raises(tmp_path):
    with pytest.raises(CheckpointError):
        GraspPredictor.from_checkpoint(tmp_path / "missing.pt")


def test_torchscript_runtime_matches_eager(tmp_path):
    path = make_random_checkpoint(tmp_path / "r.pt", seed=9)
    eager = GraspPredictor.from_checkpoint(path, runtime="eager")
    fast = GraspPredictor.from_checkpoint(path, runtime="auto")
    assert fast.runtime == "torchscript"
    depth, moduli, mask = _cell_scene()
    a, b = eager.predict(depth, moduli, K, mask, top_k=3), fast.predict(depth, moduli, K, mask, top_k=3)
    assert np.allclose(a.q, b.q, atol=1e-4) and np.allclose(a.width_px, b.width_px, atol=1e-2)
    if len(a.candidates) < 2 or a.candidates[0].quality - a.candidates[1].quality > 1e-3:  # no near-tie
        assert (a.best.center_u_px, a.best.center_v_px) == (b.best.center_u_px, b.best.center_v_px)


@pytest.mark.parametrize("weights", ["models/defgg_cnn.pt", "models/ggcnn_depth_only.pt"])
def test_more_grasps_asked_adds_ranks_without_changing_the_first(weights):
    """A small object's quality map has few local maxima (the shipped nets: one here); top_k=5 still
    gives five grasps, apart, on the object, and the first ranks are those of a smaller top_k."""
    from pathlib import Path

    from defgg_ros.grasping.postprocess import find_peaks

    predictor = GraspPredictor.from_checkpoint(Path(__file__).resolve().parents[2] / weights)
    depth = np.full((480, 640), 0.40, np.float32)
    mask = np.zeros((480, 640), np.int32)
    mask[220:250, 440:470] = 7                      # a 30 x 30 px block
    depth[mask > 0] = 0.37
    moduli = np.where(mask > 0, 2e5, 0.0).astype(np.float32)
    runs = {k: predictor.predict(depth, moduli, K, mask, top_k=k) for k in (1, 2, 5)}
    v0, u0 = runs[5].crop_offset_px[1], runs[5].crop_offset_px[0]
    crop_mask = mask[v0:v0 + 300, u0:u0 + 300] > 0
    n_maxima = len(find_peaks(runs[5].q, 10, 0.0, allowed=crop_mask, top_k=5))
    assert n_maxima < 5                             # so the test exercises the fill
    pixel = {k: [(c.center_u_px, c.center_v_px) for c in runs[k].candidates] for k in runs}
    assert len(pixel[5]) == 5 and pixel[5][:1] == pixel[1] and pixel[5][:2] == pixel[2]
    assert all(mask[int(v), int(u)] == 7 for u, v in pixel[5])
    for i, a in enumerate(pixel[5]):
        for b in pixel[5][i + 1:]:
            assert max(abs(a[0] - b[0]), abs(a[1] - b[1])) > 10
