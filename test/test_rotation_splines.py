"""The numpy rotations and splines (ports/rotation.py, ports/splines.py) give scipy's
answers to rounding: the planner's outputs must not change with the import it saves."""

import subprocess
import sys

import numpy as np
import pytest
from scipy.interpolate import CubicSpline as ScipyCubicSpline
from scipy.linalg import solve_banded as scipy_solve_banded
from scipy.spatial.transform import Rotation as ScipyRotation
from scipy.spatial.transform import RotationSpline as ScipyRotationSpline
from scipy.spatial.transform import Slerp as ScipySlerp

from cdh_planner.ports.rotation import Rotation, Slerp
from cdh_planner.ports import splines
from cdh_planner.ports.splines import CubicSpline, RotationSpline

TOL = 1e-12


def _quats(rng, n):
    q = rng.normal(size=(n, 4))
    return q / np.linalg.norm(q, axis=1, keepdims=True)


def _special_matrices():
    """Rotations by 0, tiny angles, pi/2 and pi about the axes: every branch of the
    matrix-to-quaternion choice and of the small-angle series."""
    out = []
    for axis in np.eye(3):
        for angle in (0.0, 1e-9, 1e-4, 9e-4, 1.1e-3, np.pi / 2, np.pi - 1e-6, np.pi):
            out.append(ScipyRotation.from_rotvec(angle * axis).as_matrix())
    return np.array(out)


def test_quaternion_matrix_rotvec_and_magnitude_agree_with_scipy():
    rng = np.random.default_rng(1)
    q = np.concatenate([_quats(rng, 200), ScipyRotation.from_matrix(_special_matrices()).as_quat()])
    ours, theirs = Rotation.from_quat(q), ScipyRotation.from_quat(q)
    np.testing.assert_allclose(ours.as_quat(), theirs.as_quat(), atol=TOL, rtol=0)
    np.testing.assert_allclose(ours.as_matrix(), theirs.as_matrix(), atol=TOL, rtol=0)
    np.testing.assert_allclose(ours.as_rotvec(), theirs.as_rotvec(), atol=TOL, rtol=0)
    np.testing.assert_allclose(ours.magnitude(), theirs.magnitude(), atol=TOL, rtol=0)
    m = np.concatenate([theirs.as_matrix(), _special_matrices()])
    np.testing.assert_allclose(Rotation.from_matrix(m).as_quat(),
                               ScipyRotation.from_matrix(m).as_quat(), atol=TOL, rtol=0)
    # valid rotations assumed valid: scipy's quaternions, and the checked path's bits
    np.testing.assert_allclose(Rotation.from_matrix(m, assume_valid=True).as_quat(),
                               ScipyRotation.from_matrix(m, assume_valid=True).as_quat(),
                               atol=TOL, rtol=0)
    assert np.array_equal(Rotation.from_matrix(m, assume_valid=True).as_quat(),
                          Rotation.from_matrix(m).as_quat())
    v = np.concatenate([theirs.as_rotvec(), 1e-5 * rng.normal(size=(20, 3))])
    np.testing.assert_allclose(Rotation.from_rotvec(v).as_quat(),
                               ScipyRotation.from_rotvec(v).as_quat(), atol=TOL, rtol=0)


def test_composition_inverse_and_indexing_agree_with_scipy():
    rng = np.random.default_rng(2)
    a, b = _quats(rng, 50), _quats(rng, 50)
    ours = (Rotation.from_quat(a)[:-1].inv() * Rotation.from_quat(b)[1:]).as_rotvec()
    theirs = (ScipyRotation.from_quat(a)[:-1].inv() * ScipyRotation.from_quat(b)[1:]).as_rotvec()
    np.testing.assert_allclose(ours, theirs, atol=TOL, rtol=0)
    one = Rotation.from_quat(a[0]) * Rotation.from_quat(b)
    np.testing.assert_allclose(one.as_matrix(), (ScipyRotation.from_quat(a[0])
                                                 * ScipyRotation.from_quat(b)).as_matrix(), atol=TOL)
    assert Rotation.from_quat(a[0]).as_matrix().shape == (3, 3)
    assert Rotation.from_quat(a)[3].as_quat().shape == (4,)


def test_a_matrix_off_orthogonal_is_projected_and_a_reflection_refused():
    R = ScipyRotation.from_rotvec([0.3, -0.2, 0.5]).as_matrix() + 1e-6
    np.testing.assert_allclose(Rotation.from_matrix(R).as_quat(),
                               ScipyRotation.from_matrix(R).as_quat(), atol=1e-12)
    with pytest.raises(ValueError):
        Rotation.from_matrix(np.diag([1.0, 1.0, -1.0]))


def test_slerp_agrees_with_scipy_at_and_between_the_keys():
    rng = np.random.default_rng(3)
    t = np.cumsum(rng.uniform(0.1, 1.0, 12))
    q = _quats(rng, 12)
    ts = np.concatenate([t, np.linspace(t[0], t[-1], 301)])
    ours = Slerp(t, Rotation.from_quat(q))(ts).as_matrix()
    np.testing.assert_allclose(ours, ScipySlerp(t, ScipyRotation.from_quat(q))(ts).as_matrix(),
                               atol=TOL, rtol=0)
    with pytest.raises(ValueError):
        Slerp(t, Rotation.from_quat(q))(t[-1] + 1.0)


@pytest.mark.parametrize("bc", ["natural", "clamped"])
@pytest.mark.parametrize("n", [2, 3, 40])
def test_cubic_spline_and_its_derivatives_agree_with_scipy(bc, n):
    rng = np.random.default_rng(n)
    x = np.cumsum(rng.uniform(0.01, 0.3, n))
    y = rng.normal(size=(n, 6))
    xs = np.concatenate([x, np.linspace(x[0] - 0.1, x[-1] + 0.1, 500)])
    ours, theirs = CubicSpline(x, y, bc_type=bc), ScipyCubicSpline(x, y, bc_type=bc)
    for nu in (0, 1, 2, 3):  # rounding of y, divided by dx once per derivative
        scale = np.max(np.abs(y)) / np.min(np.diff(x)) ** nu
        np.testing.assert_allclose(ours(xs, nu), theirs(xs, nu), atol=TOL * scale, rtol=0)
    assert ours(x[1]).shape == (6,)


def test_the_natural_spline_is_c2_with_zero_curvature_at_its_ends():
    x = np.array([0.0, 0.4, 0.5, 1.3, 2.0])
    y = np.sin(3 * x)
    s = CubicSpline(x, y)
    np.testing.assert_allclose(s(x), y, atol=1e-15)
    np.testing.assert_allclose(s(x[[0, -1]], 2), 0.0, atol=1e-12)
    eps = 1e-9
    for nu in (0, 1, 2):
        np.testing.assert_allclose(s(x[1:-1] - eps, nu), s(x[1:-1] + eps, nu), atol=1e-6)


@pytest.mark.parametrize("n", [2, 3, 30])
def test_rotation_spline_and_its_rates_agree_with_scipy(n):
    rng = np.random.default_rng(10 + n)
    t = np.cumsum(rng.uniform(0.05, 0.2, n))
    v = np.cumsum(rng.normal(scale=0.3, size=(n, 3)), axis=0)
    ts = np.concatenate([t, np.linspace(t[0], t[-1], 400)])
    ours = RotationSpline(t, Rotation.from_rotvec(v))
    theirs = ScipyRotationSpline(t, ScipyRotation.from_rotvec(v))
    np.testing.assert_allclose(ours(ts).as_matrix(), theirs(ts).as_matrix(), atol=TOL, rtol=0)
    for order in (1, 2):
        scale = max(1.0, float(np.max(np.abs(theirs(ts, order)))))
        np.testing.assert_allclose(ours(ts, order), theirs(ts, order), atol=TOL * scale, rtol=0)


@pytest.mark.parametrize("n", [2, 3, 30])
def test_all_derivatives_at_once_are_the_single_calls_bit_for_bit(n):
    """``derivatives`` (the pieces and rotation vectors found once, as the dynamic timing's
    geometry asks) gives each order's own call's numbers exactly."""
    rng = np.random.default_rng(20 + n)
    t = np.cumsum(rng.uniform(0.05, 0.2, n))
    ts = np.concatenate([t, np.linspace(t[0] - 0.1, t[-1] + 0.1, 300)])
    rotations = RotationSpline(t, Rotation.from_rotvec(np.cumsum(rng.normal(scale=0.3, size=(n, 3)), 0)))
    rot, rate, accel = rotations.derivatives(ts)
    assert np.array_equal(rot.as_matrix(), rotations(ts).as_matrix())
    assert np.array_equal(rate, rotations(ts, 1)) and np.array_equal(accel, rotations(ts, 2))
    cubic = CubicSpline(t, rng.normal(size=(n, 3)))
    for nu, values in zip((0, 1, 2, 3), cubic.derivatives(ts, (0, 1, 2, 3))):
        assert np.array_equal(values, cubic(ts, nu))


def test_the_banded_solve_is_scipys_below_and_above_the_dense_limit(monkeypatch):
    rng = np.random.default_rng(5)
    n = 50
    ab = rng.normal(size=(11, n))
    ab[5] += 20.0   # diagonally dominant, as the spline systems
    b = rng.normal(size=(n, 2))
    expected = scipy_solve_banded((5, 5), ab, b)
    np.testing.assert_allclose(splines.solve_banded((5, 5), ab, b), expected, atol=1e-13)
    monkeypatch.setattr(splines, "DENSE_MAX", 10)
    np.testing.assert_allclose(splines.solve_banded((5, 5), ab, b), expected, atol=1e-13)


def test_a_singular_banded_system_above_the_dense_limit_is_refused():
    ab = np.zeros((11, splines.DENSE_MAX + 1))
    with pytest.raises(np.linalg.LinAlgError):
        splines.solve_banded((5, 5), ab, np.ones(splines.DENSE_MAX + 1))


def test_a_large_banded_solve_does_not_import_scipy_linalg():
    """The wrapper alone is loaded (7 ms), not scipy.linalg (0.15 s of a plan's CPU)."""
    code = ("import sys, numpy as np\n"
            "from cdh_planner.ports.splines import DENSE_MAX, solve_banded\n"
            "n = DENSE_MAX + 5\n"
            "ab = np.zeros((11, n)); ab[5] = 2.0\n"
            "x = solve_banded((5, 5), ab, np.ones(n))\n"
            "print(float(x.max()), float(x.min()), 'scipy.linalg' in sys.modules)")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True)
    assert out.stdout.split() == ["0.5", "0.5", "False"], out.stdout + out.stderr


@pytest.mark.parametrize("bands, n, boost, seed", [(1, 60, 5.0, 7),
                                                   (5, splines.DENSE_MAX + 37, 20.0, 8)])
@pytest.mark.parametrize("dominant", [True, False])
def test_the_banded_solve_is_lapacks_to_the_last_bit(bands, n, boost, seed, dominant,
                                                      monkeypatch):
    """scipy's solve_banded((1, 1), ...) calls LAPACK's dgtsv; ours repeats its operations,
    row swaps included (a sub-diagonal larger than the diagonal), so the same numbers.
    Wider bands beyond DENSE_MAX: both call LAPACK's dgbsv through scipy's wrapper (ours
    loaded from its file, without scipy.linalg's import), the same numbers again."""
    gbsv = splines.gbsv_from_file()
    assert gbsv is not None
    monkeypatch.setattr(splines, "_GBSV", [gbsv])
    rng = np.random.default_rng(seed)
    ab = rng.normal(size=(2 * bands + 1, n))
    if dominant:
        ab[bands] += boost
    for b in (rng.normal(size=n), rng.normal(size=(n, 3))):
        np.testing.assert_array_equal(splines.solve_banded((bands, bands), ab, b),
                                      scipy_solve_banded((bands, bands), ab, b))


def test_a_singular_tridiagonal_system_is_refused():
    ab = np.array([[0.0, 1.0, 1.0], [0.0, 0.0, 0.0], [1.0, 1.0, 0.0]]) * 0
    with pytest.raises(np.linalg.LinAlgError):
        splines.solve_banded((1, 1), ab, np.ones(3))


def test_random_rotations_are_scipys():
    ours = Rotation.random(9, np.random.default_rng(4)).as_quat()
    theirs = ScipyRotation.random(9, random_state=np.random.default_rng(4)).as_quat()
    assert np.array_equal(ours, theirs)
