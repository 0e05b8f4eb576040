"""The squeeze estimate (defgg_ros/squeeze.py): readings of a known elastic model give its modulus back."""
import math

import pytest

from defgg_ros.squeeze import (
    ASSUMED_POISSON_RATIO,
    MODEL_FACTOR,
    RIGID_ABOVE_PA,
    HandCalibration,
    SqueezeError,
    SqueezeReading,
    calibrate_hand,
    estimate_modulus,
    fit_contact_exponent,
    loaded_area_m2,
    object_compression_m,
    squeeze_slope_npm,
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


def sphere_readings(e_pa, diameter_m, forces=(0.5, 1.0, 1.5, 2.0), machine_npm=math.inf,
                    poisson=ASSUMED_POISSON_RATIO):
    """What a squeeze of a sphere between two flat pads reads (Hertz at each pad, the hand in series)."""
    e_star, radius = e_pa / (1 - poisson ** 2), diameter_m / 2

    def approach_m(f):      # both contacts: 2 (9 F^2 / (16 E*^2 R))^(1/3)
        return 2 * (9 * f ** 2 / (16 * e_star ** 2 * radius)) ** (1 / 3)

    hand = 1.0 / machine_npm if math.isfinite(machine_npm) else 0.0
    return [SqueezeReading(f, diameter_m - approach_m(f) - f * hand) for f in forces]


HAND = HandCalibration(1.35e4, 1e-6, "test: a hand of 13.5 kN/m known to 1 um/N")


def test_the_hand_s_compliance_is_taken_out_in_series():
    r = readings_of(2e5, 0.04, 0.06, 0.03, machine_npm=HAND.stiffness_npm)
    est = estimate_modulus(r, 0.06, 0.03, hand=HAND, width_resolution_m=1e-6)
    assert est.youngs_modulus_pa == pytest.approx(2e5, rel=1e-6) and est.contact_law == "flat"
    # Left in, it reads the object softer than it is.
    assert estimate_modulus(r, 0.06, 0.03, width_resolution_m=1e-6).youngs_modulus_pa < 0.8 * 2e5


def test_the_band_widens_as_the_object_s_compliance_nears_the_calibration_s_noise():
    """The hand's calibration noise is in the band: a 1e6 Pa block (26 um/N of its own, the hand's sd 9.7 um/N)
    reads with a wider band than a 2e4 Pa one (1.3 mm/N: the model's own); Hertz's share 1.5 times the flat law's."""
    noisy = HandCalibration(1.35e4, 9.7e-6, "test: the simulated cell's calibration")
    band = {}
    for e_pa in (2e4, 1e6):
        r = readings_of(e_pa, 0.05, 0.05, 0.05, machine_npm=noisy.stiffness_npm)
        est = estimate_modulus(r, 0.05, 0.05, hand=noisy, width_resolution_m=1e-6)
        assert est.youngs_modulus_pa == pytest.approx(e_pa, rel=1e-6) and not est.rigid
        band[e_pa] = math.log(est.high_pa / est.youngs_modulus_pa)
    assert band[2e4] == pytest.approx(math.log(MODEL_FACTOR), rel=0.01)
    object_c = 0.05 / (1e6 * loaded_area_m2(0.05, 0.05, 0.05))
    assert band[1e6] == pytest.approx(math.hypot(math.log(MODEL_FACTOR), 9.7e-6 / object_c), rel=0.01)
    assert band[1e6] > 1.05 * band[2e4]
    sphere = sphere_readings(2e5, 0.05, machine_npm=noisy.stiffness_npm)
    hertz = estimate_modulus(sphere, 0.05, 0.05, hand=noisy, width_resolution_m=1e-6,
                             contact_radii_m=(0.025, 0.025))
    flat_c = 1.0 / squeeze_slope_npm(sphere)[0] - noisy.compliance_mpn
    assert math.log(hertz.high_pa / hertz.youngs_modulus_pa) == pytest.approx(
        math.hypot(math.log(MODEL_FACTOR), 1.5 * 9.7e-6 / flat_c), rel=0.01)


def test_an_object_no_more_compliant_than_the_calibration_s_noise_is_rigid_with_a_bound():
    # A 2e9 Pa block behind a 13.5 kN/m hand: the hand's compliance is all the squeeze resolves (74 um/N).
    r = readings_of(2e9, 0.05, 0.05, 0.05, machine_npm=HAND.stiffness_npm)
    est = estimate_modulus(r, 0.05, 0.05, hand=HAND, width_resolution_m=1e-6)
    assert est.rigid and est.lower_bound and est.high_pa == math.inf
    # The bound: the most compliant object the noise (2 sd of the calibration and of the reading) could hide.
    noise_mpn = 2 * math.hypot(HAND.compliance_sd_mpn, 1e-6 / 1.5)
    assert est.low_pa == pytest.approx(0.05 / (loaded_area_m2(0.05, 0.05, 0.05) * noise_mpn), rel=1e-9)
    # Without the calibration, the same readings are a 2e5 Pa-like number: the hand read as the object.
    assert not estimate_modulus(r, 0.05, 0.05, width_resolution_m=1e-6).rigid
    # A reading stiffer than the hand alone (a calibration a little off) is rigid too, not a negative compliance.
    stiffer = readings_of(2e9, 0.05, 0.05, 0.05, machine_npm=1.5e4)
    assert estimate_modulus(stiffer, 0.05, 0.05, hand=HAND, width_resolution_m=1e-6).rigid
    # An object whose own compliance is well above the noise is a number: 2e6 Pa behind the same hand.
    stiff = estimate_modulus(readings_of(2e6, 0.05, 0.05, 0.05, machine_npm=HAND.stiffness_npm), 0.05, 0.05,
                             hand=HAND, width_resolution_m=1e-6)
    assert stiff.youngs_modulus_pa == pytest.approx(2e6, rel=1e-3) and not stiff.rigid


def test_the_calibration_is_the_mean_compliance_of_its_squeezes_and_their_spread():
    squeezes = [readings_of(2e9, 0.05, 0.05, 0.05, machine_npm=k) for k in (1.25e4, 1.5e4)]
    hand = calibrate_hand(squeezes, "two squeezes of a steel block")
    c1, c2 = 1 / 1.25e4 + 0.05 / (2e9 * loaded_area_m2(0.05, 0.05, 0.05)), 1 / 1.5e4 + 0.05 / (
        2e9 * loaded_area_m2(0.05, 0.05, 0.05))
    assert hand.compliance_mpn == pytest.approx((c1 + c2) / 2, rel=1e-6)
    assert hand.compliance_sd_mpn == pytest.approx(abs(c1 - c2) / math.sqrt(2), rel=1e-6)
    assert "steel block" in hand.describe()
    with pytest.raises(SqueezeError, match="noise"):
        HandCalibration(1e4, -1.0)
    with pytest.raises(SqueezeError, match="one squeeze"):
        calibrate_hand([], "nothing squeezed")


@pytest.mark.parametrize("radii", [(0.0, 0.02), (-0.01, 0.02), (0.02,), (math.inf, 0.02)])
def test_contact_radii_that_are_not_two_positive_lengths_are_refused(radii):
    """A radius of 0 divided by zero, a negative one gave a complex modulus (then TypeError)."""
    with pytest.raises(SqueezeError, match="contact_radii_m"):
        estimate_modulus(sphere_readings(2e5, 0.06), 0.06, 0.06, contact_radii_m=radii)


@pytest.mark.parametrize("make, exponent", [
    (lambda: sphere_readings(2e5, 0.06), 1.5),
    (lambda: readings_of(2e5, 0.05, 0.05, 0.05), 1.0),
])
def test_the_curve_s_exponent_tells_a_curved_contact_from_a_flat_one(make, exponent):
    assert fit_contact_exponent(object_compression_m(make(), None)) == pytest.approx(exponent, abs=0.02)


@pytest.mark.parametrize("e_pa", [2e4, 2e5, 2e6])
@pytest.mark.parametrize("machine_npm", [math.inf, 1.35e4])
def test_a_sphere_s_modulus_comes_back_from_hertz(e_pa, machine_npm):
    hand = HAND if math.isfinite(machine_npm) else None
    r = sphere_readings(e_pa, 0.06, machine_npm=machine_npm)
    # Curved contacts (the perceived shape's radii) take Hertz; the exponent is fitted and reported.
    est = estimate_modulus(r, 0.06, 0.06, hand=hand, width_resolution_m=1e-7, contact_radii_m=(0.03, 0.03))
    assert est.contact_law == "hertz" and est.exponent == pytest.approx(1.5, abs=0.02)
    assert est.youngs_modulus_pa == pytest.approx(e_pa, rel=0.01)
    # Without radii, forced Hertz takes half the unloaded width (the first width plus the first force's approach).
    half = estimate_modulus(r, 0.06, 0.06, hand=hand, width_resolution_m=1e-7, contact_law="hertz")
    assert half.youngs_modulus_pa == pytest.approx(e_pa, rel=0.01)
    # The flat pads' model (the default without radii) reads the sphere's small, growing contact as much softer.
    flat = estimate_modulus(r, 0.06, 0.06, hand=hand, width_resolution_m=1e-7)
    assert flat.contact_law == "flat" and flat.youngs_modulus_pa < 0.5 * e_pa


def test_unequal_contacts_add_their_hertz_approaches():
    # A 3 cm radius at one pad and 1 cm at the other: x = (9 F^2 / (16 E*^2))^(1/3) (R1^(-1/3) + R2^(-1/3)).
    e_pa, radii = 2e5, (0.03, 0.01)
    e_star = e_pa / (1 - ASSUMED_POISSON_RATIO ** 2)
    shape = sum(r ** (-1 / 3) for r in radii)
    r = [SqueezeReading(f, 0.06 - (9 * f ** 2 / (16 * e_star ** 2)) ** (1 / 3) * shape) for f in (0.5, 1.0, 1.5, 2.0)]
    est = estimate_modulus(r, 0.06, 0.06, width_resolution_m=1e-7, contact_radii_m=radii)
    assert est.youngs_modulus_pa == pytest.approx(e_pa, rel=1e-3)


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
    ([SqueezeReading(1.0, 0.05), SqueezeReading(2.0, 0.049)], "contact_law"),
    ([SqueezeReading(f, 0.05 - 1e-4 * i) for i, f in enumerate((0.5, 1.0, 1.0, 1.5, 2.0))], "must differ"),
    # widths 50.0 / 49.7 / 49.9 / 50.0 mm: the slope is negative; it read 0 Pa (flat) or 8.9e8 Pa (hertz)
    ([SqueezeReading(f, w) for f, w in zip((0.5, 1.0, 1.5, 2.0), (0.05, 0.0497, 0.0499, 0.05))], "did not close"),
])
def test_unusable_readings_are_refused_with_the_reason(readings, says):
    with pytest.raises(SqueezeError, match=says):
        estimate_modulus(readings, 0.05, 0.05, contact_law="cone" if says == "contact_law" else "auto")


def test_the_squeeze_goes_firmer_only_while_the_compression_is_unresolved():
    from defgg_ros.squeeze import GENTLE_FORCES_N, needs_firmer

    soft = readings_of(2e5, 0.03, 0.05, 0.05, forces=GENTLE_FORCES_N)     # ~0.14 mm over the gentle forces
    stiff = readings_of(2e6, 0.05, 0.05, 0.05, forces=GENTLE_FORCES_N)    # ~0.03 mm
    assert not needs_firmer(soft, 1e-5) and needs_firmer(stiff, 1e-5)
    assert needs_firmer(soft, 1e-4)      # a hand that reads 0.1 mm must squeeze the same object harder


def test_the_executor_takes_the_hand_s_calibration_from_its_parameters():
    from types import SimpleNamespace

    from defgg_ros.nodes.executor_planning import GraspPlanning
    from defgg_ros.ros.parameters import defaults

    p = defaults("executor_node")
    goal = SimpleNamespace(measure_stiffness=False, measure_only=True)
    assert GraspPlanning._squeeze_for(goal, p).hand is None      # the schema's default: not calibrated
    p = {**p, "squeeze_hand_stiffness_npm": 13509.0, "squeeze_hand_compliance_sd_mpn": 9.7e-6,
         "squeeze_hand_calibration": "a steel block"}
    hand = GraspPlanning._squeeze_for(goal, p).hand
    assert hand == HandCalibration(13509.0, 9.7e-6, "a steel block")
