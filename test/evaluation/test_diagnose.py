"""Diagnostics: label statistics of a real dataset on disk and grasp shifts between moduli."""
import pytest

from defgg_ros.data.synthetic import write_synthetic_dataset
from defgg_ros.evaluation import diagnose


def test_label_stats_count_every_trial(tmp_path):
    write_synthetic_dataset(tmp_path, n_objects=3, trials_per_scene=5)
    stats = diagnose.label_stats(tmp_path)
    per_e = stats["per_modulus"]
    assert set(per_e) == {"2e+04", "2e+05", "2e+06", "2e+09"}
    assert sum(v["trials"] for v in per_e.values()) == 3 * 4 * 5
    for v in per_e.values():
        assert v["labelled"] + v["sim_failed"] == v["trials"] and 0 <= v["positive"] <= v["labelled"]
    for v in stats["label_agreement"].values():
        assert 0 <= v["same"] <= v["compared"]
    assert "Training labels by modulus" in diagnose.diagnostics_markdown(stats, None)


def test_label_stats_carry_the_datasets_signal_report_and_its_verdict(tmp_path):
    """The synthetic labels depend on where a box is grasped and on its stiffness: the oracle gap is large."""
    write_synthetic_dataset(tmp_path, n_objects=3, trials_per_scene=5)
    signal = diagnose.label_stats(tmp_path)["signal"]
    assert signal["labelled"] == 60 and signal["oracle"]["objects"] == 3
    best = signal["oracle"]["best"]
    assert best["gap_points"] == pytest.approx(100 * (best["aware"] - best["blind"])) and best["gap_points"] > 5
    md = "\n".join(diagnose.signal_lines(signal, str(tmp_path)))
    assert f"best grasp +{best['gap_points']:.1f} points" in md
    assert '- Can carry "stiffness changes which grasp is good"' in md
    assert diagnose.signal_lines(None, None) == []


def test_label_locality_finds_the_spatial_order_of_rule_based_labels(tmp_path):
    """The synthetic labels are a rule of the grasp's place on the box: near candidates share a label
    far more often than distant ones."""
    write_synthetic_dataset(tmp_path, n_objects=3, trials_per_scene=40)
    locality = diagnose.label_stats(tmp_path)["locality"]
    for loc in locality.values():       # soft and rigid boxes both follow a rule
        assert loc["scenes"] > 0 and loc["near"]["pairs"] > 20 and loc["far"]["pairs"] > 100
        assert loc["near"]["rate"] >= 0.8 and loc["near"]["rate"] > loc["far"]["rate"] + 0.2
    assert "| soft | " in diagnose.diagnostics_markdown(diagnose.label_stats(tmp_path), None)


def _entry(model, obj, e, xy, width=0.04):
    view = {"experiment": "main", "model": model, "object_name": obj, "youngs_modulus_pa": e}
    return {"view": view, "grasps": [{"position_m": [*xy, 0.02], "width_m": width}]}


def test_plan_shifts_measure_how_far_the_best_grasp_moves():
    plans = [_entry("stiff", "a", 2e9, (0.0, 0.0)), _entry("stiff", "a", 2e4, (0.01, 0.0), 0.03),
             _entry("depth", "a", 2e9, (0.0, 0.0)), _entry("depth", "a", 2e4, (0.0, 0.0))]
    shifts = diagnose.plan_shifts(plans)
    assert shifts["stiff"]["2e+04"]["mean_shift_mm"] == 10.0
    assert shifts["stiff"]["2e+04"]["moved_over_5mm"] == 1
    assert abs(shifts["stiff"]["2e+04"]["mean_width_change_mm"] - 10.0) < 1e-9
    assert shifts["depth"]["2e+04"]["mean_shift_mm"] == 0.0


def _trial(experiment, success, u=100, yaw=0.0, width=0.04, **extra):
    return {"experiment": experiment, "model": "stiff", "object_set": "common", "object": "a",
            "youngs_modulus_pa": 2e5, "rank": 0, "task": "shake", "success": success,
            "grasp": {"center_u_px": u, "center_v_px": 50, "yaw_rad": yaw, "width_m": width}, **extra}


def test_replicate_flips_compare_only_same_pixel_grasps_with_their_views_main_trial():
    import math

    records = [_trial("main", True),
               _trial("sensitivity", False, width=0.0402, yaw=math.pi - 0.01),   # same pixel, outcome differs
               _trial("sensitivity", True, width=0.0404),                        # same pixel, same outcome
               _trial("sensitivity", False, u=140),                              # moved: not a replicate
               _trial("sensitivity", None),                                      # simulation failed
               _trial("sensitivity", False, reused_from="k")]                    # the main trial itself
    rep = diagnose.replicate_flips(records)
    assert rep["pairs"] == 2 and rep["outcome_differs"] == 1 and rep["rate"] == 0.5
    assert abs(rep["median_width_change_mm"] - 0.3) < 1e-9
    assert abs(rep["median_angle_change_deg"] - math.degrees(0.005)) < 1e-9     # a half turn is the same grasp
    assert "outcome differs in 1 (50.0 %)" in diagnose.diagnostics_markdown(None, None, rep)
    assert diagnose.replicate_flips([_trial("main", True)]) is None


def test_quality_ranking_compares_grasps_of_one_view_that_ended_differently():
    def ranked(success, quality, obj="a", rank=0, experiment="main"):
        r = _trial(experiment, success, rank=rank, input_error_pct=0.0)
        r["object"], r["grasp"]["quality"] = obj, quality
        return r

    records = [ranked(True, 0.9), ranked(False, 0.8, rank=1), ranked(False, 0.95, rank=2),
               ranked(True, 0.7, rank=3),
               ranked(True, 0.5, obj="b"), ranked(False, 0.5, obj="b", rank=1),              # a tie: one half
               ranked(None, 0.99, obj="b", rank=2),                 # simulation failed: not graded
               ranked(False, 0.1, obj="c", experiment="sensitivity"), ranked(True, 0.2, obj="c")]
    rank = diagnose.quality_ranking(records)
    # view a: held {0.9, 0.7} x failed {0.8, 0.95}: only 0.9 > 0.8 is in order, 1 of 4; view b: a tie, 1/2;
    # view c: its only other trial is a sensitivity trial, so no pair
    assert rank == {"shake|common|stiff": {"pairs": 5, "concordant": 1.5, "rate": 0.3}}
    md = diagnose.diagnostics_markdown(None, None, None, rank)
    assert "| shake | common | stiff | 5 | 30.0 % |" in md
    assert diagnose.quality_ranking([ranked(True, 0.9)]) is None


def _labelled(e_pa, accels, measured=None):
    from types import SimpleNamespace

    mean = sum(accels) / len(accels) if accels else 0.0
    return SimpleNamespace(youngs_modulus_pa=e_pa, shake_accels_mps2=accels, label=bool(accels) and mean >= 25.0,
                           sim={"shake_measured": measured} if measured else {})


def test_grasp_choice_splits_the_held_acceleration_into_within_and_between_scenes():
    """Two soft scenes: one whose grasps all hold 40 m/s^2, one whose grasps hold 30 or drop in the
    lift (0): the variance within scenes is 2 * 15^2 * 2 of a total that the scene means add to."""
    held_40 = [_labelled(2e4, [40.0] * 4) for _ in range(4)]
    # An unmeasured direction (imputed 50 by the generator) must not count.
    mixed = [_labelled(2e4, [30.0, 30.0, 50.0], [True, True, False]), _labelled(2e4, [30.0] * 3),
             _labelled(2e4, None), _labelled(2e4, None)]
    choice = diagnose._grasp_choice([held_40, mixed, [_labelled(2e9, [50.0] * 2)]])
    soft = choice["soft"]
    values = [40.0] * 4 + [30.0, 30.0, 0.0, 0.0]
    grand = sum(values) / 8
    total = sum((v - grand) ** 2 for v in values)
    assert soft["within_scene_share"] == pytest.approx(4 * 15.0 ** 2 / total)
    assert soft["scenes"] == 2 and soft["trials"] == 8 and soft["scenes_with_both_labels"] == 1
    assert soft["random_candidate_positive"] == pytest.approx(0.75) and soft["best_candidate_positive"] == 1.0
    assert "rigid" not in choice          # a single rigid trial has no spread to split
    assert "| soft | 2 | 8 |" in "\n".join(diagnose._grasp_choice_markdown(choice))


def test_near_pairs_are_split_by_their_grasp_heights():
    """Two candidates on one pixel: at the same height they agree, 12 mm apart they do not."""
    from types import SimpleNamespace

    from defgg_ros.data.format import GraspRect

    def cand(z_m, label):
        return SimpleNamespace(youngs_modulus_pa=2e4, label=label, position_m=[0.0, 0.0, z_m],
                               rect=GraspRect(150.0, 150.0, 0.0, 40.0, 20.0))
    locality = diagnose._label_locality([[cand(0.020, True), cand(0.021, True), cand(0.033, False)]])["soft"]
    assert locality["near"]["pairs"] == 3 and locality["near_same_height"] == {"same": 1, "pairs": 1, "rate": 1.0}
    assert locality["near_height_apart"] == {"same": 0, "pairs": 2, "rate": 0.0}


def test_positive_rate_by_height_offset_bins_every_labelled_trial(tmp_path):
    write_synthetic_dataset(tmp_path, n_objects=2, trials_per_scene=6)
    by_height = diagnose.label_stats(tmp_path)["positive_rate_by_height_offset_mm"]
    assert sum(v["trials"] for body in by_height.values() for v in body.values()) == 2 * 4 * 6
    # Synthetic trials sit at z = 0, always >= 10 mm below the executor's grasp height.
    assert all(v["trials"] == 0 for body in by_height.values() for k, v in body.items() if k != "< -10")
    assert "| soft | " in "\n".join(diagnose._height_offset_markdown(by_height))


def _twist(e_pa, status, accels=None, measured=None, **extra):
    rec = {"task": "twist", "experiment": "main", "input_error_pct": 0.0, "youngs_modulus_pa": e_pa,
           "status": status, "accels": accels, "measured": measured}
    rec.update(extra)
    return rec


def test_twist_by_axis_counts_an_axis_only_where_the_trial_reached_it():
    full, short = 500.0, 120.0
    recs = [
        _twist(2e4, "ok", [full] * 6, [True] * 6),                                        # held everywhere
        _twist(2e4, "ok", [full, full, short, 0, 0, 0], [True, True, True] + [False] * 3),  # lost about y
        _twist(2e4, "ok", [full, full, full, full, short, 0], [True] * 5 + [False]),        # lost about z
        _twist(2e4, "lift_failed"),
        _twist(2e4, "exploded"),                                                          # not a grasp outcome
        _twist(2e4, "ok", [full] * 6, [True] * 6, experiment="sensitivity", input_error_pct=30.0),
        _twist(2e9, "ok", [short, 0, 0, 0, 0, 0], [True] + [False] * 5),                   # lost about x
        _twist(2e9, "ok", [full] * 6, [True] * 6, task="shake"),
    ]
    axes = diagnose.twist_by_axis(recs)
    assert list(axes) == ["2e+04", "2e+09"]
    soft = axes["2e+04"]
    assert (soft["trials"], soft["lift_failed"], soft["lifted"]) == (4, 1, 3)
    assert soft["axes"] == {"x": [3, 3], "y": [2, 3], "z": [1, 2]}
    assert axes["2e+09"]["axes"] == {"x": [0, 1], "y": [0, 0], "z": [0, 0]}
    md = "\n".join(diagnose._twist_axes_markdown(axes))
    assert "| 2e+04 | 4 | 1 | 3 | 100.0 % of 3 | 66.7 % of 3 | 50.0 % of 2 |" in md
    assert diagnose.twist_by_axis([_twist(2e4, "ok", [full] * 6, task="shake")]) is None


def test_model_grasp_pairs_split_the_two_models_grasps_into_identical_near_and_apart():
    import math

    def trial(model, success, xy, yaw=0.0, obj="a", rank=0, sim_key=None, experiment="main"):
        r = _trial(experiment, success, yaw=yaw, rank=rank, input_error_pct=0.0,
                   sim_key=sim_key or f"{model}{obj}{rank}")
        r["model"], r["object"], r["grasp"]["position_m"] = model, obj, [*xy, 0.02]
        return r

    records = [trial("stiff", True, (0.0, 0.0)), trial("depth", False, (0.003, 0.0), yaw=math.pi - 0.1),  # near
               trial("stiff", True, (0.0, 0.0), rank=1), trial("depth", True, (0.0, 0.004), yaw=0.5, rank=1),  # turned
               trial("stiff", True, (0.0, 0.0), obj="b"), trial("depth", False, (0.02, 0.0), obj="b"),         # apart
               trial("stiff", True, (0.0, 0.0), obj="c", sim_key="k"),
               trial("depth", True, (0.0, 0.0), obj="c", sim_key="k"),                             # identical
               trial("stiff", None, (0.0, 0.0), obj="d"), trial("depth", True, (0.0, 0.0), obj="d"),  # not graded
               trial("stiff", True, (0.0, 0.0), obj="e"),                                           # one model
               trial("depth", False, (0.0, 0.0), obj="e", experiment="sensitivity")]
    pairs = diagnose.model_grasp_pairs(records)
    assert pairs == {"shake|common": {"pairs": 4, "identical": 1, "near": 1, "near_differ": 1, "apart": 2,
                                      "apart_differ": 1, "median_distance_mm": 4.0}}
    md = diagnose.diagnostics_markdown(None, None, model_pairs=pairs)
    assert "| shake | common | 4 | 1 | 1 of 1 (100.0 %) | 1 of 2 (50.0 %) | 4.0 |" in md
    assert diagnose.model_grasp_pairs([trial("stiff", True, (0.0, 0.0))]) is None
