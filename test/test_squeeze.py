"""The squeeze estimate (defgg_ros/squeeze.py): readings of a known elastic model give its modulus back."""
import math

import pytest

from defgg_ros.squeeze import (
    RIGID_ABOVE_PA,
    SqueezeError,
    SqueezeReading,
    estimate_modulus,
    loaded_area_m2,
)

pytestmark = pytest.mark.unit


def readings_of(e_pa, width_m, face_w, face_h, forces=(0.5, 1.0, 1.5, 2.0), machine_npm=math.inf):
    """What a squeeze of the module's series model reads (exact widths)."""
    area = loaded_area_m2(width_m, face_w, face_h)
    compliance = width_m / (e_pa * area) + (1.0 / machine_npm if math.isfinite(machine_npm) else 0.0)
    return [SqueezeReading(f, width_m - (f - forces[0]) * compliance) for f in forces]


@pytest.mark.parametrize("e_pa", [2e4, 2e5, 2e6])
def test_the_model_s_own_readings_give_its_modulus_back(e_pa):
    est = estimate_modulus(readings_of(e_pa, 0.05, 0.05, 0.05), 0.05, 0.05, width_resolution_m=1e-6)
    assert est.youngs_modulus_pa == pytest.approx(e_pa, rel=1e-6)
    assert est.low_pa < e_pa < est.high_pa and not est.lower_bound and not est.rigid


def test_the_machine_s_compliance_is_taken_out():
    r = readings_of(2e5, 0.04, 0.06, 0.03, machine_npm=2e4)
    assert estimate_modulus(r, 0.06, 0.03, machine_stiffness_npm=2e4, width_resolution_m=1e-6) \
        .youngs_modulus_pa == pytest.approx(2e5, rel=1e-6)
    # Left in, it reads the object softer than it is.
    assert estimate_modulus(r, 0.06, 0.03, width_resolution_m=1e-6).youngs_modulus_pa < 0.8 * 2e5


def test_a_compression_within_the_width_resolution_is_only_a_lower_bound():
    hard = (0.5, 1.0, 10.0, 20.0)   # unresolved at gentle forces, the squeeze goes on harder
    est = estimate_modulus(readings_of(2e9, 0.05, 0.05, 0.05, forces=hard), 0.05, 0.05, width_resolution_m=1e-5)
    assert est.lower_bound and est.rigid and est.high_pa == math.inf and est.low_pa >= RIGID_ABOVE_PA
    assert "rigid" in est.describe()
    soft_enough = estimate_modulus(readings_of(2e6, 0.05, 0.05, 0.05, forces=(0.5, 1.0)), 0.05, 0.05,
                                   width_resolution_m=1e-4)
    assert soft_enough.lower_bound and not soft_enough.rigid and soft_enough.youngs_modulus_pa <= 2e6


def test_the_loaded_area_spreads_from_the_pad_and_stops_at_the_face():
    assert loaded_area_m2(0.0, 1.0, 1.0, 0.02, 0.018) == pytest.approx(0.02 * 0.018)
    assert loaded_area_m2(0.04, 1.0, 1.0, 0.02, 0.018) == pytest.approx(0.04 * 0.038)
    assert loaded_area_m2(0.04, 0.03, 0.025, 0.02, 0.018) == pytest.approx(0.03 * 0.025)


@pytest.mark.parametrize("readings, says", [
    ([SqueezeReading(1.0, 0.05)], "two forces"),
    ([SqueezeReading(1.0, 0.05), SqueezeReading(1.0, 0.049)], "must differ"),
    ([SqueezeReading(1.0, 0.05), SqueezeReading(2.0, float("nan"))], "finite"),
    ([SqueezeReading(1.0, 0.05), SqueezeReading(2.0, 0.0502)], "grew with the force"),
])
def test_unusable_readings_are_refused_with_the_reason(readings, says):
    with pytest.raises(SqueezeError, match=says):
        estimate_modulus(readings, 0.05, 0.05)


def test_the_squeeze_goes_firmer_only_while_the_compression_is_unresolved():
    from defgg_ros.squeeze import GENTLE_FORCES_N, needs_firmer

    soft = readings_of(2e5, 0.03, 0.05, 0.05, forces=GENTLE_FORCES_N)     # ~0.14 mm over the gentle forces
    stiff = readings_of(2e6, 0.05, 0.05, 0.05, forces=GENTLE_FORCES_N)    # ~0.03 mm
    assert not needs_firmer(soft, 1e-5) and needs_firmer(stiff, 1e-5)
    assert needs_firmer(soft, 1e-4)      # a hand that reads 0.1 mm must squeeze the same object harder
