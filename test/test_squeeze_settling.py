"""A settling step in a squeeze (defgg_ros/squeeze.py, "Settling"): an object that turns or settles between the pads
at one gentle force is not read as compression."""
import pytest

from defgg_ros.squeeze import (
    GENTLE_FORCES_N,
    HandCalibration,
    SqueezeReading,
    estimate_modulus,
    needs_firmer,
    without_settling_step,
)

pytestmark = pytest.mark.unit

# The simulated cell's hand (sim_bringup/config/sim_cell.yaml) and its width resolution.
CELL_HAND = HandCalibration(13509.0, 9.7e-6, "the simulated cell's calibration")
RESOLUTION_M = 1e-5
# Stored squeezes of rigid (2e9 Pa) held-out objects (results/squeeze/readings.jsonl, yaw 0): egad_test_20_c6 drops
# 3.4 mm between 0.5 and 1 N and then only the hand's ~35 um/N; the star prism egad_test_05_c2 0.54 mm between 1
# and 1.5 N.
RIGID_STEP_FIRST_M = (0.0638636385, 0.0604501614, 0.0604333374, 0.0604153012)
RIGID_STEP_MIDDLE_M = (0.0539097160, 0.0538884038, 0.0533503600, 0.0533295270)


def squeeze(widths_m, forces_n=GENTLE_FORCES_N):
    return [SqueezeReading(f, w) for f, w in zip(forces_n, widths_m)]


@pytest.mark.parametrize("widths_m, step_m", [(RIGID_STEP_FIRST_M, 3.41e-3), (RIGID_STEP_MIDDLE_M, 5.4e-4)])
def test_a_rigid_body_that_settles_between_the_pads_reads_rigid(widths_m, step_m):
    estimate = estimate_modulus(squeeze(widths_m), 0.05, 0.05, hand=CELL_HAND, width_resolution_m=RESOLUTION_M,
                                contact_radii_m=(0.02, 0.02))
    assert estimate.rigid
    assert estimate.settling_step_m == pytest.approx(step_m, rel=0.02)
    assert "settling step left out" in estimate.describe()


def test_the_longer_run_of_readings_on_either_side_of_the_step_is_kept():
    first, _ = without_settling_step(squeeze(RIGID_STEP_FIRST_M), RESOLUTION_M)
    assert [r.force_n for r in first] == [1.0, 1.5, 2.0]
    middle, _ = without_settling_step(squeeze(RIGID_STEP_MIDDLE_M), RESOLUTION_M)
    assert [r.force_n for r in middle] == [1.5, 2.0]      # a tie: the settled side


@pytest.mark.parametrize("compliance_um_per_n", [(900.0, 700.0, 600.0), (3500.0, 2300.0, 100.0), (708.7, 105.2, 101.8)])
def test_an_elastic_compression_is_left_as_it_is(compliance_um_per_n):
    """A smooth curve and stored soft squeezes' uneven intervals stay whole: common_pear at 5e4 Pa (2.9x the others)
    and egad_test_05_c2 at 1.5e6 Pa (6.8x: the most uneven soft squeeze stored)."""
    widths = [0.05]
    for c in compliance_um_per_n:
        widths.append(widths[-1] - 0.5 * c * 1e-6)
    readings = squeeze(widths)
    kept, step = without_settling_step(readings, RESOLUTION_M)
    assert kept == readings and step == 0.0
    assert estimate_modulus(readings, 0.05, 0.05, hand=CELL_HAND, width_resolution_m=RESOLUTION_M).settling_step_m == 0


def test_a_step_must_stand_out_from_the_width_resolution_too():
    """Fingers that do not move at the gentle forces and then close 33 mm at the firm 10 N (the stored squeeze of
    common_ring at 3e4 Pa, held at the hand's full opening): the firm interval is not a gentle one, so its
    compression stays in (4,088 um/N, far above any ratio of the gentle intervals' zero)."""
    ring = squeeze((0.08, 0.08, 0.08, 0.08, 0.0472982), (*GENTLE_FORCES_N, 10.0))
    assert without_settling_step(ring, RESOLUTION_M) == (ring, 0.0)
    tiny = squeeze((0.05, 0.05, 0.05 - 10 * RESOLUTION_M, 0.05 - 10 * RESOLUTION_M))
    assert without_settling_step(tiny, 1e-4)[1] == 0.0       # 0.1 mm of step at a 0.1 mm resolution: not resolved


def test_after_a_settling_step_the_squeeze_goes_firmer():
    """The step is not compression: what is left (0.035 mm) is not resolved, so the executor squeezes harder."""
    assert needs_firmer(squeeze(RIGID_STEP_FIRST_M), RESOLUTION_M)
