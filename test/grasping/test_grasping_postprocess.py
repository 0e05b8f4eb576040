"""Post-processing: angle decoding and wrap-around, peaks, masks, ranges."""
import math

import numpy as np
import pytest

from defgg_ros.grasping.config import PostProcessConfig
from defgg_ros.grasping.postprocess import angle_from_cos_sin, find_peaks, grasps_from_maps, maps_from_network


def _raw(angle_rad=0.3, width_px=60.0, q=None):
    raw = np.zeros((4, 300, 300), np.float32)
    raw[0] = 0.0 if q is None else q
    raw[1], raw[2] = math.cos(2 * angle_rad), math.sin(2 * angle_rad)
    raw[3] = width_px / 150.0
    return raw


@pytest.mark.parametrize("angle", [-math.pi / 2 + 1e-3, -1.2, -0.3, 0.0, 0.7, math.pi / 2 - 1e-3])
def test_angle_is_recovered_in_range(angle):
    maps = maps_from_network(_raw(angle))
    assert maps.angle_rad[150, 150] == pytest.approx(angle, abs=1e-5)


def test_angles_across_the_wrap_are_not_averaged_to_zero():
    # Left half +89 deg, right half -89 deg: the same physical grasp axis.
    raw = _raw(0.0)
    a, b = math.radians(89), math.radians(-89)
    raw[1, :, :150], raw[2, :, :150] = math.cos(2 * a), math.sin(2 * a)
    raw[1, :, 150:], raw[2, :, 150:] = math.cos(2 * b), math.sin(2 * b)
    angle = maps_from_network(raw, PostProcessConfig(angle_sigma_px=3.0)).angle_rad
    assert np.all(np.abs(angle[:, 140:160]) > math.radians(85))


def test_angle_from_cos_sin_range():
    rng = np.random.default_rng(0)
    angle = angle_from_cos_sin(rng.normal(size=1000), rng.normal(size=1000))
    assert angle.min() >= -math.pi / 2 and angle.max() <= math.pi / 2


def test_outputs_are_clipped_to_their_ranges():
    raw = _raw(width_px=400.0, q=np.full((300, 300), 1.7, np.float32))
    maps = maps_from_network(raw)
    assert maps.q.max() == 1.0 and maps.width_px.max() == 150.0
    raw[0], raw[3] = -2.0, -1.0
    maps = maps_from_network(raw)
    assert maps.q.min() == 0.0 and maps.width_px.min() == 0.0


def test_a_quality_overshoot_is_ranked_at_its_top_not_at_the_clipped_plateau_edge():
    # A linear quality output above 1 over a whole object (the fem_v5 pair's maps): clipped to 1 it is
    # one plateau of ties, which the search once resolved in raster order, at the object's top-left edge.
    v, u = np.mgrid[0:300, 0:300]
    on_object = (np.abs(u - 150) <= 30) & (np.abs(v - 120) <= 30)
    q = np.where(on_object, 1.6 - 0.01 * np.hypot(u - 152, v - 118), 0.0).astype(np.float32)
    maps = maps_from_network(_raw(0.2, 50.0, q))
    assert np.sum(maps.q[on_object] == 1.0) > 1000     # the plateau the clip makes
    grasps = grasps_from_maps(maps, allowed=on_object, top_k=5, fill=True)
    assert (grasps[0].center_u_px, grasps[0].center_v_px) == (152, 118)
    assert grasps[0].quality == 1.0                    # reported in [0, 1]
    assert len({(g.center_u_px, g.center_v_px) for g in grasps}) == 5


def test_planted_peak_is_found_with_its_parameters():
    v, u = np.mgrid[0:300, 0:300]
    q = 0.8 * np.exp(-((u - 210) ** 2 + (v - 95) ** 2) / (2 * 6.0**2)).astype(np.float32)
    grasps = grasps_from_maps(maps_from_network(_raw(-0.9, 42.0, q)), top_k=3)
    assert (grasps[0].center_u_px, grasps[0].center_v_px) == (210, 95)
    assert grasps[0].angle_rad == pytest.approx(-0.9, abs=1e-4)
    assert grasps[0].width_px == pytest.approx(42.0, rel=1e-4)
    # Blurring a sigma-6 bump with sigma 2 lowers its peak to 0.8 * 36 / (36 + 4).
    assert grasps[0].quality == pytest.approx(0.72, abs=1e-3)


def test_peaks_respect_distance_threshold_ranking_and_mask():
    q = np.zeros((100, 100), np.float32)
    q[20, 20], q[20, 25], q[70, 70], q[50, 10] = 0.9, 0.8, 0.6, 0.05
    assert find_peaks(q, 10, 0.1, top_k=5) == [(20, 20), (70, 70)]   # (20, 25) too close, 0.05 too low
    assert find_peaks(q, 3, 0.1, top_k=5) == [(20, 20), (20, 25), (70, 70)]
    mask = np.zeros_like(q, bool)
    mask[60:, 60:] = True
    assert find_peaks(q, 10, 0.1, allowed=mask, top_k=5) == [(70, 70)]


def test_plateau_gives_one_peak_and_flat_map_falls_back_to_best_allowed():
    q = np.zeros((50, 50), np.float32)
    q[10:13, 10:13] = 0.5
    assert len(find_peaks(q, 5, 0.0, top_k=4)) == 1
    mask = np.zeros((50, 50), bool)
    mask[30:, 30:] = True
    assert find_peaks(np.zeros((50, 50), np.float32), 5, 0.0, allowed=mask) == [(30, 30)]
    assert find_peaks(q, 5, 0.0, allowed=np.zeros((50, 50), bool)) == []
    with pytest.raises(ValueError):
        find_peaks(q, 5, 0.0, allowed=np.ones((10, 10), bool))
    with pytest.raises(ValueError):
        find_peaks(q, 5, 0.0, top_k=0)


def test_a_saturated_plateau_gives_peaks_min_distance_apart_in_scan_order():
    """A quality map clipped at 1 over a large area (the shipped net on the bench scene): thousands of
    equal maxima; the kept peaks are the first in row-major order that keep min_distance apart."""
    q = np.zeros((80, 80), np.float32)
    q[10:70, 10:70] = 1.0
    peaks = find_peaks(q, min_distance_px=10, threshold=0.0, top_k=5)
    assert peaks[0] == (10, 10)
    assert len(peaks) == 5
    for i, a in enumerate(peaks):
        for b in peaks[i + 1:]:
            assert max(abs(a[0] - b[0]), abs(a[1] - b[1])) > 10
    assert peaks == sorted(peaks)    # equal quality: stable order, row-major


@pytest.mark.parametrize("config", [PostProcessConfig(), PostProcessConfig(angle_sigma_px=2.6, width_sigma_px=0.0)])
def test_values_at_one_pixel_are_the_full_maps_values(config):
    """Ranking reads angle and width at the peaks only (at_pixel); they must be the full maps' values,
    borders included (where the blur replicates the edge)."""
    raw = np.random.default_rng(3).normal(size=(4, 300, 300)).astype(np.float32)
    pixels = [(0, 0), (299, 299), (0, 150), (3, 296), (150, 7), (120, 201)]
    lazy = [maps_from_network(raw, config).at_pixel(v, u) for v, u in pixels]
    full = maps_from_network(raw, config)
    expected = [(full.angle_rad[v, u], full.width_px[v, u]) for v, u in pixels]
    assert np.allclose(lazy, expected, atol=1e-5)
    assert full.at_pixel(120, 201) == pytest.approx(expected[-1], abs=1e-6)   # from the computed maps


def test_fill_adds_ranks_after_the_maxima_apart_from_every_pick():
    """One quality blob (a small object) has one local maximum; fill gives the next best pixels, each
    more than min_distance from every pick, after the maxima, so the maxima keep their ranks."""
    vv, uu = np.mgrid[0:100, 0:100]
    q = np.exp(-((vv - 50) ** 2 + (uu - 40) ** 2) / 400.0).astype(np.float32)
    q[85, 85] = 0.05                                            # a second, weak local maximum
    assert find_peaks(q, 10, 0.0, top_k=5) == [(50, 40), (85, 85)]
    peaks = find_peaks(q, 10, 0.0, top_k=5, fill=True)
    assert peaks[:2] == [(50, 40), (85, 85)] and len(peaks) == 5
    for i, a in enumerate(peaks):
        for b in peaks[i + 1:]:
            assert max(abs(a[0] - b[0]), abs(a[1] - b[1])) > 10
    fills = peaks[2:]
    assert [q[p] for p in fills] == sorted((q[p] for p in fills), reverse=True)
    assert all(q[p] > 0.5 for p in fills)                       # on the blob's flanks, next to its top
    mask = np.zeros_like(q, bool)
    mask[40:60, 30:50] = True                                   # room for one pick only beside the top
    assert find_peaks(q, 10, 0.0, allowed=mask, top_k=5, fill=True) == [(50, 40)]
