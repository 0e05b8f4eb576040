"""Diagnostics: label statistics of a real dataset on disk and grasp shifts between moduli."""
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
