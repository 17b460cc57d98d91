"""The elastic platform's stiffness (``model.elastic.platform_stiffness``) and the stiff
nominal (``wrench.stiff_nominal``) on CoGiRo where the centred nominal turns (the path of
test_elastic_commands.py): finite differences of the balance, its identities (symmetric at
an equilibrium, affine in the tensions), the equilibrium's sensitivity to a wrench along
the soft mode, and the nominal's conditions (stiff, the same wrench, nearest, kept where
already stiff)."""

from dataclasses import replace

import numpy as np
import pytest

from conftest import CONFIG
from cdh_planner.model.elastic import (equilibrium_poses, platform_stiffness, soft_poses,
                                       static_load, unstretched_lengths, wrench_balance)
from cdh_planner.model.robot import load_robot
from cdh_planner.ports import Rotation, Slerp
from cdh_planner.wrench import (cable_vectors, least_stiffness, rule_tensions, screw_jacobian,
                                stiff_nominal)

START = (np.array([1.047984, -1.939296, 4.927995]),
         np.array([0.233006, 0.752711, -0.022944, 0.615311]))
GOAL = (np.array([1.115362, -1.982235, 4.924133]),
        np.array([0.232084, 0.751918, -0.024812, 0.616555]))


@pytest.fixture(scope="module")
def robot():
    return load_robot(CONFIG / "cogiro.yaml")


def poses(n=9):
    s = np.linspace(0.0, 1.0, n)
    p = (1 - s)[:, None] * START[0] + s[:, None] * GOAL[0]
    return p, Slerp([0.0, 1.0], Rotation.from_quat([START[1], GOAL[1]]))(s).as_matrix()


def jacobian(robot, p, R):
    u = cable_vectors(robot, p, R)
    return screw_jacobian(robot, u / np.linalg.norm(u, axis=-1)[..., None])


def lengths(robot, p, R):
    d = p[:, None, :] + robot.platform_anchors @ R.transpose(0, 2, 1) - robot.base_anchors
    return np.linalg.norm(d, axis=-1)


def test_stiffness_is_the_balance_differentiated(robot):
    """K is minus the change of the cables' wrench about p (the load's included) per
    [dp; dtheta], by central differences of ``wrench_balance``'s residual with the cables
    held at their unstretched lengths; symmetric where the tensions balance the load."""
    p, R = poses(3)
    t = rule_tensions(robot, p, R)[0]
    L0 = unstretched_lengths(robot, lengths(robot, p, R), t)
    K = platform_stiffness(robot, p, R, t)
    h = 1e-6
    for k in range(6):
        rows = []
        for sign in (1, -1):
            dx = np.zeros(6)
            dx[k] = sign * h
            R2 = Rotation.from_rotvec(np.broadcast_to(dx[3:], (len(p), 3))).as_matrix() @ R
            p2 = p + dx[:3]
            res = wrench_balance(robot, L0, p2, R2, *static_load(robot, len(p)),
                                 bilateral=True, jacobian=False)[0]
            res[:, 3:] -= np.cross(p, res[:, :3])  # about the unmoved p (the frame of K)
            rows.append(res)
        np.testing.assert_allclose((rows[0] - rows[1]) / (2 * h), K[:, :, k],
                                   rtol=1e-5, atol=1e-5 * np.abs(K).max())
    res = wrench_balance(robot, L0, p, R, *static_load(robot, len(p)), bilateral=True)
    _, jac, _ = res
    jac[:, 3:, :] -= np.cross(p[:, None, :], jac[:, :3, :].transpose(0, 2, 1)).transpose(0, 2, 1)
    np.testing.assert_allclose(jac, jac.transpose(0, 2, 1), atol=1e-9 * np.abs(jac).max())


def test_stiffness_is_affine_in_the_tensions(robot):
    p, R = poses(3)
    t = rule_tensions(robot, p, R)[0]
    n = np.linalg.svd(jacobian(robot, p, R))[2][:, 6, :] * 300.0      # null-space N
    K0, K1, K2 = (platform_stiffness(robot, p, R, t + a * n) for a in (0.0, 1.0, 2.5))
    np.testing.assert_allclose(K2 - K0, 2.5 * (K1 - K0), atol=1e-7 * np.abs(K0).max())


def test_the_soft_mode_is_the_equilibriums_sensitivity(robot):
    """A wrench dw about p along the least stiff mode moves the elastic equilibrium by
    K^-1 dw = dw / lambda_min (to 1 %: second order), the platform's soft mode."""
    p, R = poses(3)
    t = rule_tensions(robot, p, R)[0]
    L0 = unstretched_lengths(robot, lengths(robot, p, R), t)
    lam, vec = np.linalg.eigh(platform_stiffness(robot, p, R, t))
    force, moment, arm = (x.copy() for x in static_load(robot, len(p)))
    dw = 0.05 * vec[:, :, 0]                                 # 0.05 N (N m) along the soft mode
    # about the origin: [dF; dM_p + p x dF]
    eq = equilibrium_poses(robot, L0, p, R, force + dw[:, :3],
                           moment + dw[:, 3:] + np.cross(p, dw[:, :3]), arm)
    assert eq.ok.all()
    dtheta = Rotation.from_matrix(eq.R @ R.transpose(0, 2, 1)).as_rotvec()
    moved = np.concatenate([eq.p - p, dtheta], axis=1)
    predicted = dw / lam[:, :1]
    np.testing.assert_allclose(moved, predicted, rtol=0, atol=1e-2 * np.abs(predicted).max())


def test_the_compiled_soft_test_is_the_least_eigenvalue_below_kappa(robot):
    """``soft_poses`` (compiled K, Cholesky of K - kappa I) says soft exactly where
    eigvalsh of ``platform_stiffness`` is below kappa, at kappa on either side of every
    pose's least eigenvalue by 1e-9 of the largest; poses outside ``where`` and non-finite
    tensions are never soft."""
    p, R = poses(17)
    t = rule_tensions(replace(robot, cable_stiffness=None), p, R)[0]
    lam = np.linalg.eigvalsh(platform_stiffness(robot, p, R, t))
    everywhere = np.ones(len(p), dtype=bool)
    for k in range(len(p)):
        for sign in (1.0, -1.0):
            kappa = lam[k, 0] + sign * 1e-9 * lam[k, -1]
            np.testing.assert_array_equal(soft_poses(robot, p, R, t, everywhere, kappa),
                                          lam[:, 0] < kappa)
    kappa = np.mean(np.sort(lam[:, 0])[8:10])  # between two poses' least eigenvalues
    where = np.arange(len(p)) % 2 == 0
    t_nan = t.copy()
    t_nan[4, 2] = np.nan
    soft = soft_poses(robot, p, R, t_nan, where, kappa)
    expected = (lam[:, 0] < kappa) & where
    expected[4] = False
    np.testing.assert_array_equal(soft, expected)


def test_the_stiff_nominal(robot):
    """Along the turn: lambda_min(K) >= kappa where the rule's nominal was softer, the same
    wrench (J t0' = J t0), the nearest such nominal (its shift along the null-space gradient
    of lambda_min: the projection's optimality), t0 kept where already stiff."""
    p, R = poses(17)
    J = jacobian(robot, p, R)
    centred = rule_tensions(replace(robot, cable_stiffness=None), p, R)[0]  # the rule's own
    t = stiff_nominal(robot, p, R, J, centred)
    kappa = least_stiffness(robot)
    lam_before = np.linalg.eigvalsh(platform_stiffness(robot, p, R, centred))[:, 0]
    lam, vec = np.linalg.eigh(platform_stiffness(robot, p, R, t))
    soft = lam_before < kappa
    assert soft.any() and (~soft).any()                       # the path crosses into the turn
    assert np.all(lam[:, 0] >= kappa - 1e-6 * lam[:, -1])
    np.testing.assert_array_equal(t[~soft], centred[~soft])
    np.testing.assert_allclose(np.einsum("nij,nj->ni", J, t - centred), 0.0, atol=1e-6)
    N = np.linalg.svd(J)[2][:, 6:, :]
    shift = np.einsum("nai,ni->na", N, t - centred)[soft]
    Ka = np.stack([platform_stiffness(robot, p, R, t + N[:, a]) - platform_stiffness(robot, p, R, t)
                   for a in range(2)], axis=1)
    g = np.einsum("ni,naij,nj->na", vec[:, :, 0], Ka, vec[:, :, 0])[soft]
    cos = np.sum(shift * g, axis=1) / np.linalg.norm(shift, axis=1) / np.linalg.norm(g, axis=1)
    assert np.all(cos > 1 - 1e-4), cos


def test_six_and_rigid_cables_keep_the_rules_nominal(robot):
    p, R = poses(3)
    J = jacobian(robot, p, R)
    t0 = rule_tensions(robot, p, R)[0]
    rigid = replace(robot, cable_stiffness=None)
    assert stiff_nominal(rigid, p, R, J, t0) is t0
    six = stiff_nominal(robot, p, R, J[:, :, :6], t0[:, :6])
    np.testing.assert_array_equal(six, t0[:, :6])


def test_the_least_stiffness_of_the_robot_file(robot):
    """``robot.least_stiffness`` is kappa (CoGiRo's file: 250 N/m); absent, 0: stability
    alone (the turn's nominal then moves less, to lambda_min = 0); test_robot_file refuses
    a negative one."""
    assert least_stiffness(robot) == 250.0
    p, R = poses(17)
    J = jacobian(robot, p, R)
    centred = rule_tensions(replace(robot, cable_stiffness=None), p, R)[0]
    stable = replace(robot, least_stiffness=None)
    assert least_stiffness(stable) == 0.0
    t_stable, t_stiff = (stiff_nominal(r, p, R, J, centred) for r in (stable, robot))
    K = platform_stiffness(robot, p, R, t_stable)
    lam = np.linalg.eigvalsh(K)
    assert np.all(lam[:, 0] >= -1e-6 * lam[:, -1]) and lam[:, 0].min() < 1.0
    assert np.all(np.linalg.norm(t_stable - centred, axis=1)
                  <= np.linalg.norm(t_stiff - centred, axis=1) + 1e-9)


def test_the_stiff_shift_stays_within_reach_of_the_limits():
    """Far from the workspace no nominal keeps robot2_8's platform stable and the projection
    would go on to 1e13 N: each shift stops one tension range beyond the limits (a nominal
    outside them, out of the domain either way), with the rule's wrench, and poses outside
    ``where`` (the facet test's refusals) keep the rule's nominal."""
    robot = load_robot(CONFIG / "robot2_8.yaml")
    rng = np.random.default_rng(8)
    p = rng.uniform(-1.0, 1.0, (300, 3)) + robot.base_anchors.mean(axis=0)
    R = Rotation.from_rotvec(rng.normal(scale=0.6, size=(300, 3))).as_matrix()
    J = jacobian(robot, p, R)
    centred = rule_tensions(replace(robot, cable_stiffness=None), p, R)[0]
    ok = np.all(np.isfinite(centred), axis=1)
    p, R, J, centred = p[ok], R[ok], J[ok], centred[ok]
    assert len(p) > 100
    kept = stiff_nominal(robot, p, R, J, centred, np.zeros(len(p), dtype=bool))
    np.testing.assert_array_equal(kept, centred)
    t = stiff_nominal(robot, p, R, J, centred)
    moved = np.any(t != centred, axis=1)
    assert moved.any()
    span = robot.tension_max - robot.tension_min
    assert np.all(t[moved] <= robot.tension_max + span + 1e-6)
    assert np.all(t[moved] >= robot.tension_min - span - 1e-6)
    np.testing.assert_allclose(np.einsum("nij,nj->ni", J, t - centred), 0.0,
                               atol=1e-9 * np.abs(t).max())
