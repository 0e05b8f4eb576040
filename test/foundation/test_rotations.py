"""The one quaternion <-> matrix conversion (defgg_ros/rotations.py) that perception, control and the TF
helpers share: every branch of Shepperd's method, the w >= 0 sign, and the caller's error type."""
import numpy as np
import pytest

from defgg_ros.rotations import matrix_to_quaternion_xyzw, quaternion_xyzw_to_matrix, unit_quaternion_xyzw

pytestmark = pytest.mark.unit


class CallerError(ValueError):
    pass


def _half_turns():
    """Rotations of pi about x, y and z: trace -1, so each of the three non-trace branches runs once."""
    return [np.diag([1.0, -1.0, -1.0]), np.diag([-1.0, 1.0, -1.0]), np.diag([-1.0, -1.0, 1.0])]


def test_round_trip_is_a_proper_rotation_with_w_non_negative():
    rng = np.random.default_rng(7)
    for _ in range(200):
        q = rng.normal(size=4)
        q /= np.linalg.norm(q)
        rotation = quaternion_xyzw_to_matrix(q)
        assert rotation @ rotation.T == pytest.approx(np.eye(3), abs=1e-12)
        assert np.linalg.det(rotation) == pytest.approx(1.0, abs=1e-12)
        back = matrix_to_quaternion_xyzw(rotation)
        assert back[3] >= 0.0
        assert back == pytest.approx(q if q[3] >= 0 else -q, abs=1e-9)


@pytest.mark.parametrize("axis", [0, 1, 2])
def test_half_turns_take_the_branch_of_their_axis(axis):
    q = matrix_to_quaternion_xyzw(_half_turns()[axis])
    expected = np.zeros(4)
    expected[axis] = 1.0
    assert q == pytest.approx(expected, abs=1e-12)
    assert quaternion_xyzw_to_matrix(q) == pytest.approx(_half_turns()[axis], abs=1e-12)


def test_near_unit_quaternions_are_normalised_and_others_refused_in_the_callers_type():
    assert np.linalg.norm(unit_quaternion_xyzw([0.0, 0.0, 0.0, 1.0005])) == pytest.approx(1.0, abs=1e-15)
    with pytest.raises(CallerError, match="unit norm"):
        unit_quaternion_xyzw([0.0, 0.0, 0.0, 1.01], CallerError)
    with pytest.raises(CallerError, match="4 finite numbers"):
        quaternion_xyzw_to_matrix([0.0, float("nan"), 0.0, 1.0], CallerError)
    with pytest.raises(ValueError, match="4 finite numbers"):
        quaternion_xyzw_to_matrix([0.0, 0.0, 1.0])
