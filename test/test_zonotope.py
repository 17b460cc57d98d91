"""Wrench feasibility for m >= 6 cables (the facet test of ``wrench``, docs/more-cables.md): m = 6 is the
closed form; for any m an independent linear programme (scipy's HiGHS: is there t in the
box with J t = w?) confirms the facet test's answers; the tension rule's band is exact."""

import dataclasses
import tempfile
from pathlib import Path

import numpy as np
import pytest
import yaml
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st
from scipy.optimize import linprog

import wrench_reference as zt
from cdh_planner import wrench as fz
from cdh_planner.model.pose import rotation_tt
from cdh_planner.model.robot import load_robot, robot_from_dict

from conftest import CONFIG
from lp_oracle import lp_holds, pose_pieces

P_REF = np.array([0.0, 0.0, 1.2])  # m: the random robots' reference pose (identity rotation)
DECIDED = 1e-4  # |normalised margin| above which the LP's tolerance (1e-7) cannot blur the answer


def random_robot(rng, m, frame="load"):
    """An m-cable robot dict, z up: base anchors on a 2.5 m sphere around P_REF, platform
    anchors 0.3 m out with a twist (moment authority), random limits, a random SPD
    ellipsoid, and a load wrench J t that tensions inside the box hold at P_REF."""
    d = rng.normal(size=(m, 3))
    d /= np.linalg.norm(d, axis=1, keepdims=True)
    base = P_REF + 2.5 * d
    twist = rng.normal(size=(m, 3))
    plat = 0.3 * d + 0.25 * (twist - (twist * d).sum(1, keepdims=True) * d)
    tmin, tmax = rng.uniform(5, 20, m), rng.uniform(400, 800, m)
    u = plat + P_REF - base
    u /= np.linalg.norm(u, axis=1, keepdims=True)
    w = np.vstack([u.T, np.cross(base, u).T]) @ (tmin + (tmax - tmin) * rng.uniform(0.35, 0.65, m))
    Q, _ = np.linalg.qr(rng.normal(size=(6, 6)))
    E = Q @ np.diag(np.r_[rng.uniform(1, 4, 3) / 20.0 ** 2, rng.uniform(1, 4, 3) / 5.0 ** 2]) @ Q.T
    E *= 10.0 ** rng.uniform(-1.0, 1.0)
    return {"winch_names": [f"w{i}" for i in range(m)], "base_anchors": base.ravel().tolist(),
            "platform_anchors": plat.ravel().tolist(), "length_min": 0.05, "length_max": 10.0,
            "tension_min": tmin.tolist(), "tension_max": tmax.tolist(),
            "load": {"force": w[:3].tolist(), "moment": (w[3:] - np.cross(P_REF, w[:3])).tolist()},
            "wrench_ellipsoid": {"frame": frame, "matrix": (0.5 * (E + E.T)).ravel().tolist()}}


def random_poses(rng, n, spread=None):
    """n poses around P_REF within ``spread`` m (random if None) and tilts up to 4 spread rad."""
    spread = rng.uniform(0.05, 0.3) if spread is None else spread
    p = P_REF + rng.uniform(-spread, spread, (n, 3))
    tau = np.column_stack([rng.uniform(-np.pi, np.pi, n), rng.uniform(0, 1.5 * spread, n),
                           rng.uniform(-spread, spread, n)])
    return p, tau


def check_against_lp(robot, J, w0, L, f, rng, boundary=8):
    """Each decided pose: infeasible -> the ellipsoid's extreme point along the worst facet
    normal is LP-infeasible; feasible -> ``boundary`` random boundary wrenches are all
    LP-feasible. Returns (feasible poses, infeasible poses) checked."""
    counts = [0, 0]
    for q in np.flatnonzero(np.abs(f.wrench_margin) > DECIDED):
        if f.wrench_margin[q] < 0:
            n = zt.facet_normal(J[q], f.wrench_facet[q], f.wrench_facet_up[q])
            g = L[q].T @ n
            extreme = w0[q] + L[q] @ g / np.linalg.norm(g)
            assert not lp_holds(J[q], extreme, robot), (q, f.wrench_margin[q])
            counts[1] += 1
        else:
            u = rng.normal(size=(boundary, 6))
            for w in w0[q] + (L[q] @ (u / np.linalg.norm(u, axis=1, keepdims=True)).T).T:
                assert lp_holds(J[q], w, robot), (q, f.wrench_margin[q])
            counts[0] += 1
    return counts


# ---------------------------------------------------------------- m = 6: the closed form

def _variants():
    """Every robot of config/ with six cables, and robot 2 with a base-frame ellipsoid,
    an offset and a load point off P (branches the paper's robots do not take)."""
    robots = {p.stem: load_robot(p) for p in sorted(CONFIG.glob("*.yaml"))}
    robots = {k: r for k, r in robots.items() if len(r.winch_names) == 6}
    doc = yaml.safe_load((CONFIG / "robot2.yaml").read_text())["cdh_planner"]["ros__parameters"]["robot"]
    doc["wrench_ellipsoid"] = {"frame": "base", "matrix": [1e2, 2e2, 1e2, 1e4, 1e4, 2e4],
                               "offset": [0.1, 0.0, -0.2, 0.0, 0.001, 0.0]}
    doc["load"]["point"] = [0.01, -0.02, 0.015]
    doc["load"].pop("mass"), doc["load"].pop("inertia")
    robots["robot2_base_frame"] = robot_from_dict(doc)
    return robots


SIX = _variants()


@pytest.mark.parametrize("name", SIX)
def test_six_cables_agree_with_the_closed_form(name):
    """Margins (relative to max(1, |margin|)) and bands to 1e-9, and the same feasibility,
    binding constraint (names included) and singular poses, on 3000 random poses."""
    robot = SIX[name]
    rng = np.random.default_rng(11)
    n = 3000
    p = np.column_stack([rng.uniform(-0.1, 0.1, n), rng.uniform(-0.1, 0.1, n), rng.uniform(0.15, 0.45, n)])
    tau = np.column_stack([rng.uniform(-np.pi, np.pi, n), rng.uniform(0, np.pi, n), rng.uniform(-np.pi, np.pi, n)])
    a, b = fz.wrench_feasibility(robot, p, tau), zt.facet_test(robot, p, tau)
    assert 0.01 < a.feasible.mean() < 0.99  # both answers are exercised
    np.testing.assert_array_equal(a.singular, b.singular)
    np.testing.assert_array_equal(a.feasible, b.feasible)
    np.testing.assert_array_equal(a.binding, b.binding)
    ok = ~a.singular
    assert np.all(np.abs(a.margin - b.margin)[ok] <= 1e-9 * np.maximum(1.0, np.abs(a.margin[ok])))
    np.testing.assert_allclose(np.abs(a.det_j), b.det_j, rtol=1e-6)
    well = ok & (np.abs(a.det_j) > 1e-6)  # bands of near-singular poses lose digits in both
    scale = np.maximum(1.0, np.abs(a.tension_nominal[well]))
    assert np.all(np.abs(a.tension_nominal - b.tension_nominal)[well] <= 1e-9 * scale)
    assert np.all(np.abs(a.tension_spread - b.tension_spread)[well] <= 1e-9 * scale)
    np.testing.assert_allclose(a.margins, b.margins, rtol=0, atol=1e-9 * np.abs(a.margins).max())
    assert set(np.unique(b.tension_status)) <= {fz.STATUS_OK, fz.STATUS_INFEASIBLE, fz.STATUS_SINGULAR}


def test_six_cable_facet_slack_is_the_closed_form_slack_over_the_row_norm():
    """The m = 6 reduction (docs/more-cables.md): facet "all but k", normal r_k / |r_k|
    (r_k row k of J^-1), has slack (t_max_k - f0_k - v_k) / |r_k| newtons."""
    robot = SIX["robot2"]
    rng = np.random.default_rng(5)
    p = np.column_stack([rng.uniform(-0.05, 0.05, 50), rng.uniform(-0.05, 0.05, 50), rng.uniform(0.25, 0.4, 50)])
    tau = np.column_stack([rng.uniform(-np.pi, np.pi, 50), rng.uniform(0, 0.6, 50), rng.uniform(-0.5, 0.5, 50)])
    J, w0, L, f = pose_pieces(robot, p, tau)
    a = fz.wrench_feasibility(robot, p, tau)
    rows = np.linalg.norm(np.linalg.inv(J), axis=-1)
    slack = np.concatenate([(robot.tension_max - a.tension_max) / rows,
                            (a.tension_min - robot.tension_min) / rows], axis=1)
    np.testing.assert_allclose(f.margin_newtons, slack.min(axis=1), rtol=1e-9, atol=1e-12)


# ---------------------------------------------------------------- any m: the LP oracle

@pytest.mark.parametrize("m", [6, 7, 8, 12])
def test_facet_test_agrees_with_the_lp(m):
    """Random robots and poses: every decided answer confirmed by the LP, both answers seen."""
    rng = np.random.default_rng(100 + m)
    seen = np.zeros(2, int)
    for k in range(6):
        robot = robot_from_dict(random_robot(rng, m, frame=("load", "base")[k % 2]))
        J, w0, L, f = pose_pieces(robot, *random_poses(rng, 25))
        seen += check_against_lp(robot, J, w0, L, f, rng)
    assert seen.min() >= 10, seen


@pytest.mark.parametrize("m", [7, 8, 12])
def test_compiled_kernel_matches_the_direct_facet_test(m):
    """The compiled facet test (basis coordinates) = facet_margins (a normal per subset from J's
    columns, as written) and tension_rule (numpy), to 1e-9."""
    rng = np.random.default_rng(200 + m)
    robot = robot_from_dict(random_robot(rng, m))
    J, w0, L, f = pose_pieces(robot, *random_poses(np.random.default_rng(200 + m), 200))
    mn, mr, arg, hi = zt.facet_margins(np.ascontiguousarray(J), w0, np.ascontiguousarray(L),
                                       robot.tension_min, robot.tension_max, zt.facet_subsets(m))
    np.testing.assert_allclose(f.margin_newtons, mn, rtol=1e-9, atol=1e-9)
    np.testing.assert_allclose(f.wrench_margin, mr, rtol=1e-9, atol=1e-12)
    p, tau = random_poses(np.random.default_rng(200 + m), 200)  # the same poses again
    R = rotation_tt(tau)
    out = zt.uncentred_rule(robot, J, fz.load_point(robot, p, R))  # the rule before centring
    t0, v = zt.tension_rule(robot, J, w0, L)
    np.testing.assert_allclose(out[0], t0, rtol=1e-9, atol=1e-9)
    np.testing.assert_allclose(out[1], v, rtol=1e-9, atol=1e-9)
    np.testing.assert_allclose(f.tension_spread, v, rtol=1e-9, atol=1e-9)  # centring keeps v


# ---------------------------------------------------------------- the tension rule's band

@pytest.mark.parametrize("m", [7, 8, 12])
def test_tension_band_is_exact_for_the_rule(m):
    """t(w) = t0 + P (w - w0) with P = D J^T (J D J^T)^-1 and t0 the centred nominal:
    J t0 = w0 to 1e-9; over random wrenches of the ellipsoid every t(w) lies in t0 +- v,
    and each bound is attained (at w0 + L (P L)_i^T / v_i); where the status is ok, t0 +- v
    lies in the limits and the zonotope holds the ellipsoid (a rule that holds every wrench
    proves it)."""
    rng = np.random.default_rng(300 + m)
    robot = robot_from_dict(random_robot(rng, m))
    J, w0, L, f = pose_pieces(robot, *random_poses(rng, 60, spread=0.3))
    t0, v = f.tension_nominal, f.tension_spread
    np.testing.assert_allclose(np.einsum("nij,nj->ni", J, t0), w0, rtol=0, atol=1e-9 * np.abs(w0).max())
    D = (robot.tension_max - robot.tension_min) ** 2
    for q in range(len(w0)):
        P = D[:, None] * J[q].T @ np.linalg.inv(J[q] * D @ J[q].T)
        u = rng.normal(size=(6, 50))
        t = t0[q][:, None] + P @ L[q] @ (u / np.linalg.norm(u, axis=0))
        assert np.all(np.abs(t - t0[q][:, None]) <= v[q][:, None] * (1 + 1e-9))
        PL = P @ L[q]
        attained = t0[q] + np.einsum("ij,ij->i", PL, PL / v[q][:, None])
        np.testing.assert_allclose(attained, t0[q] + v[q], rtol=1e-9)
    ok = f.tension_status == fz.STATUS_OK
    assert ok.any() and (~ok).any()
    assert np.all(f.wrench_margin[ok] > 0)
    assert np.all((t0 - v >= robot.tension_min)[ok]) and np.all((t0 + v <= robot.tension_max)[ok])
    exceeds = f.tension_status == fz.STATUS_EXCEEDS
    assert np.all(f.wrench_margin[exceeds] > 0)


def _best_shift(robot, J, t0, v):
    """The oracle for the centring: the largest least normalised band slack any null-space
    shift of the nominal reaches (an LP over (z, s), scipy HiGHS)."""
    D = robot.tension_max - robot.tension_min
    m = len(D)
    N = np.linalg.svd(J)[2][6:].T  # null space of J (m, m - 6)
    A = np.vstack([np.column_stack([-N / D[:, None], np.ones(m)]), np.column_stack([N / D[:, None], np.ones(m)])])
    b = np.concatenate([(t0 - robot.tension_min - v) / D, (robot.tension_max - v - t0) / D])
    res = linprog(np.r_[np.zeros(m - 6), -1.0], A_ub=A, b_ub=b,
                  bounds=[(None, None)] * (m - 6) + [(None, 1.0)], method="highs")
    assert res.status == 0, res.message
    return res.x[-1]


def test_a_rule_without_its_weights_or_name_is_refused_when_it_registers():
    class Nameless(fz.TensionRule):
        def weights(self, robot):
            return robot.tension_max

    class Weightless(fz.TensionRule):
        name = "weightless"

    for cls, what in ((Nameless, "name"), (Weightless, "weights")):
        with pytest.raises(TypeError, match=f"{cls.__name__} lacks {what}"):
            fz.register(cls)
    assert "weightless" not in fz.RULES


@pytest.mark.parametrize("rule", sorted(fz.RULES))
def test_every_registered_rule_holds_the_wrench_and_its_band_is_exact(rule):
    """Each rule of wrench.RULES (chosen by robot.tension_rule) on robot2_8, rigid cables:
    its map is a right inverse, J P = I; its t0 holds the nominal wrench, J t0 = w0; its
    band is v = |rows of P L|, so t0 + P (w - w0) over the ellipsoid's wrenches stays in
    t0 +- v and reaches it along L^T P_i."""
    robot = dataclasses.replace(load_robot(CONFIG / "robot2_8.yaml"), cable_stiffness=None,
                                tension_rule=rule)
    rng = np.random.default_rng(31)
    p = np.array([0.0, 0.0, 0.3]) + rng.uniform(-0.05, 0.05, (20, 3))
    R = rotation_tt(rng.uniform(-0.2, 0.2, (20, 3)))
    t0, v = fz.rule_tensions(robot, p, R)
    u = fz.cable_vectors(robot, p, R)
    J = fz.screw_jacobian(robot, u / np.linalg.norm(u, axis=-1)[..., None])
    P = fz.tension_map(robot, J)
    c = fz.load_point(robot, p, R)
    L = fz.inverse_ellipsoid_factor(robot, c)
    np.testing.assert_allclose(J @ P, np.broadcast_to(np.eye(6), (20, 6, 6)), atol=1e-9)
    w0 = fz.nominal_wrench(robot, c)
    np.testing.assert_allclose(np.einsum("nij,nj->ni", J, t0), w0, atol=1e-9 * np.abs(w0).max())
    PL = P @ L
    np.testing.assert_allclose(v, np.linalg.norm(PL, axis=-1), rtol=1e-9)
    x = rng.normal(size=(20, 50, 6))
    moved = np.einsum("nij,nkj->nki", PL, x / np.linalg.norm(x, axis=-1, keepdims=True))
    assert np.all(np.abs(moved) <= v[:, None, :] * (1 + 1e-12))
    extreme = np.einsum("nij,nij->ni", PL, PL / np.linalg.norm(PL, axis=-1, keepdims=True))
    np.testing.assert_allclose(extreme, v, rtol=1e-12)


@pytest.mark.parametrize("name", ["cogiro", "robot2_8"])
def test_centred_nominal_holds_every_pose_a_shift_can_hold(name):
    """The centring's guarantee (docs/more-cables.md): where some null-space shift fits the
    band with normalised slack above 2 m CENTRE_MU (the LP says), the centred rule's status
    is ok; and it never reports ok where no shift fits."""
    robot = load_robot(CONFIG / f"{name}.yaml")
    rng = np.random.default_rng(9)
    centre, half = ((0.0, 0.0, 2.5), (6.0, 4.5, 2.0)) if name == "cogiro" else ((0.0, 0.0, 0.3), (0.1, 0.1, 0.15))
    p = np.asarray(centre) + rng.uniform(-1, 1, (150, 3)) * np.asarray(half)
    tau = np.column_stack([rng.uniform(-np.pi, np.pi, 150), rng.uniform(0, 0.3, 150), rng.uniform(-0.3, 0.3, 150)])
    J, w0, L, f = pose_pieces(robot, p, tau)
    m, checked = len(robot.winch_names), 0
    for q in np.flatnonzero(f.wrench_margin > 0):
        best = _best_shift(robot, J[q], f.tension_nominal[q], f.tension_spread[q])
        if best > 2 * m * zt.CENTRE_MU * (1 + 1e-6):
            assert f.tension_status[q] == fz.STATUS_OK, (q, best)
            checked += 1
        if best < -1e-9:
            assert f.tension_status[q] == fz.STATUS_EXCEEDS
    assert checked > 50


def test_centred_nominal_is_smooth_along_a_motion():
    """The nominal a controller follows: along 2000 poses 1 mm apart on CoGiRo, no jump
    (second differences O(step^2), not O(1))."""
    robot = load_robot(CONFIG / "cogiro.yaml")
    s = np.linspace(0.0, 2.0, 2001)[:, None]
    p = np.array([-1.0, -0.5, 2.0]) + s * np.array([1.0, 0.6, 0.4])
    tau = np.column_stack([np.full(len(s), 0.5), 0.05 + 0.05 * s[:, 0], np.zeros(len(s))])
    f = zt.facet_test(robot, p, tau)
    assert np.all(f.tension_status == fz.STATUS_OK)
    second = np.abs(np.diff(f.tension_nominal, 2, axis=0)).max()
    first = np.abs(np.diff(f.tension_nominal, axis=0)).max()
    assert second < 0.05 * first, (first, second)


# ---------------------------------------------------------------- robot files with random m

@settings(max_examples=20, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(m=st.integers(6, 12), seed=st.integers(0, 2 ** 32 - 1), frame=st.sampled_from(["load", "base"]))
def test_robot_files_with_any_m(m, seed, frame):
    """A robot file with m winch names is read with m cables and its feasibility answers,
    shapes and statuses hold together, decided answers confirmed by the LP."""
    rng = np.random.default_rng(seed)
    doc = {"cdh_planner": {"ros__parameters": {"robot": random_robot(rng, m, frame)}}}
    with tempfile.TemporaryDirectory() as tmp:
        path = Path(tmp) / f"robot{m}.yaml"
        path.write_text(yaml.safe_dump(doc))
        robot = load_robot(path)
    assert robot.base_anchors.shape == (m, 3) and robot.tension_max.shape == (m,)
    J, w0, L, f = pose_pieces(robot, *random_poses(rng, 8))
    assert f.tension_nominal.shape == f.margins[:, 2, :].shape == (8, m)
    assert np.all((f.margin > 0) == ((f.wrench_margin > 0) & (f.margins[:, :2].min(axis=(1, 2)) > 0)))
    assert np.all((f.tension_status == fz.STATUS_INFEASIBLE) == (f.wrench_margin <= 0))
    assert np.all(np.sign(f.margin_newtons) == np.sign(f.wrench_margin))
    check_against_lp(robot, J, w0, L, f, rng, boundary=3)


def test_fewer_than_six_or_degenerate_anchors_are_refused():
    from cdh_planner.errors import InputError
    rng = np.random.default_rng(1)
    doc = random_robot(rng, 5)
    with pytest.raises(InputError, match="robot.winch_names = .*expected 6 to 16"):
        robot_from_dict(doc)
    doc = random_robot(rng, 8)
    doc["base_anchors"] = [v for i in range(8) for v in (0.5 * i, 0.0, 3.0)]  # on one line
    with pytest.raises(InputError, match="robot.base_anchors = .*collinear"):
        robot_from_dict(doc)


def test_threaded_kernel_gives_the_serial_answers():
    """From PARALLEL_MIN poses the kernels work in chunks (on threads where that pays): the
    same numbers as smaller batches."""
    rng = np.random.default_rng(400)
    robot = robot_from_dict(random_robot(rng, 8))
    p, tau = random_poses(rng, zt.PARALLEL_MIN + 100, spread=0.3)
    whole = zt.facet_test(robot, p, tau)
    parts = [zt.facet_test(robot, p[k:k + 1000], tau[k:k + 1000]) for k in range(0, len(p), 1000)]
    for name in ("margin", "margin_newtons", "tension_nominal", "tension_spread", "binding"):
        np.testing.assert_array_equal(getattr(whole, name), np.concatenate([getattr(f, name) for f in parts]))


@pytest.mark.parametrize("name, centre, half", [
    ("robot2", (0.0, 0.0, 0.3), 0.2), ("robot2_8", (0.0, 0.0, 0.3), 0.2),
    ("cogiro", (0.0, 0.0, 2.5), 5.0), ("ipanema2", (0.0, 0.0, 3.0), 3.0)])
def test_wrench_margin_is_the_exact_tests_margin_and_binding(name, centre, half):
    """``wrench_margin`` (the dense motion check's test: for m > 6 the facet test without the
    tension rule) gives ``wrench_feasibility``'s margin and binding bit for bit: feasible,
    infeasible (lengths, facets) and singular poses (a platform anchor on its base anchor)."""
    robot = load_robot(CONFIG / f"{name}.yaml")
    rng = np.random.default_rng(11)
    scale = np.repeat([0.05, 0.2, 1.0], 200)[:, None]  # near the centre, then farther
    p = centre + scale * rng.uniform(-1.0, 1.0, (600, 3)) * half
    tau = np.column_stack([rng.uniform(-np.pi, np.pi, 600), rng.uniform(0.0, 0.3, 600),
                           rng.uniform(-0.3, 0.3, 600)]) * scale
    R = rotation_tt(tau)
    R[0] = np.eye(3)
    p[0] = robot.base_anchors[0] - robot.platform_anchors[0]  # cable 1 of length 0: singular
    full, alone = fz.wrench_feasibility(robot, p, R=R), fz.wrench_margin(robot, p, R=R)
    np.testing.assert_array_equal(alone.margin, full.margin)
    np.testing.assert_array_equal(alone.binding, full.binding)
    assert full.binding[0] == "singular" and 0 < np.sum(full.margin > 0) < len(p) - 100
    assert len(set(full.binding)) > 4
