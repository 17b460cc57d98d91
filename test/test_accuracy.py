"""Pose accuracy from the winches (cdh_planner.accuracy): the exact worst case over the box
of winch errors against brute force over all 2^m vertices, the error map against finite
differences of the robot's own kinematics and statics, and the planner's accuracy limits
kept at every dense sample of a planned path."""

import dataclasses
import itertools
import json
import zlib

import numpy as np
import pytest
from scipy.spatial.transform import Rotation, Slerp

from conftest import CONFIG
from cdh_planner import cli
from cdh_planner.accuracy import (AccuracyLimits, bound, box_max_norm, error_map,
                                  pose_accuracy)
from cdh_planner.wrench import band_feasibility, rule_tensions
from cdh_planner.commands.plan import plan_document
from cdh_planner.errors import InputError
from cdh_planner.wrench import load_point, nominal_wrench, screw_jacobian
from cdh_planner.model import elastic
from cdh_planner.model.kinematics import cable_lengths, forward_kinematics, rotation_vector_exp
from cdh_planner.model.pose import Pose, rotation_from_quaternion, rotation_tt
from cdh_planner.model.robot import load_robot
from cdh_planner.model.task import SphereTask
from cdh_planner.pictures.slices import FEASIBLE, INACCURATE, SliceView, compute_slice
from cdh_planner.planner import Planner
from cdh_planner.ros.core.diagnostics import Health, health_status
from cdh_planner.settings import PlannerSettings
from cdh_planner.status import Status
from cdh_planner.trajectory.path_check import check_path

ROBOTS = ("robot1", "robot2", "robot2_8", "cogiro")


def robot_variants():
    """(id, robot) of every shipped robot, as shipped (elastic) and with rigid cables."""
    out = []
    for name in ROBOTS:
        robot = load_robot(CONFIG / f"{name}.yaml")
        assert robot.cable_stiffness is not None and robot.length_error is not None
        out += [(f"{name}-elastic", robot),
                (f"{name}-rigid", dataclasses.replace(robot, cable_stiffness=None))]
    return out


VARIANTS = robot_variants()


def random_poses(robot, n, rng):
    """n random non-singular poses (p (n, 3) m, R (n, 3, 3)) inside the base anchors' box,
    tilted up to 0.3 rad."""
    lo, hi = robot.base_anchors.min(axis=0), robot.base_anchors.max(axis=0)
    span = np.where(hi - lo > 0, hi - lo, 0.5 * (hi - lo).max())
    mid = 0.5 * (lo + hi) + np.where(hi - lo > 0, 0.0, 0.3 * span)  # a planar base: below it
    p = mid + (rng.random((4 * n, 3)) - 0.5) * 0.6 * span
    R = Rotation.from_rotvec(rng.normal(scale=0.15, size=(4 * n, 3))).as_matrix()
    G = error_map(robot, p, R)
    ok = np.all(np.isfinite(G), axis=(1, 2))
    assert ok.sum() >= n
    return p[ok][:n], R[ok][:n]


def brute_force(M, e):
    """max ||M dl|| over every vertex of the box |dl_i| <= e_i, by itertools (N,)."""
    m = M.shape[-1]
    V = np.array(list(itertools.product((-1.0, 1.0), repeat=m))) * e  # (2^m, m)
    return np.linalg.norm(np.einsum("nxk,vk->nvx", M, V), axis=2).max(axis=1)


def numpy_error_map(robot, p, R, tensions):
    """The error map written in numpy (the compiled one's reference): A (N, 6, m) with
    columns [u_i; (a_i - p) x u_i], G = A^-T (six cables) or (A K A^T)^-1 A K."""
    d = p[:, None, :] + np.einsum("nij,kj->nki", R, robot.platform_anchors) - robot.base_anchors
    L = np.linalg.norm(d, axis=-1)
    u = d / L[..., None]
    A = np.concatenate([u, np.cross(robot.base_anchors - p[:, None, :], u)], axis=-1)
    A = np.swapaxes(A, -1, -2)
    if A.shape[-1] == 6:
        return np.linalg.inv(np.swapaxes(A, -1, -2))
    k = (elastic.axial_stiffness(robot, elastic.unstretched_lengths(robot, L, tensions))
         if elastic.is_elastic(robot) else 1.0 / L)
    AK = A * k[:, None, :]
    return np.linalg.solve(AK @ np.swapaxes(A, -1, -2), AK)


@pytest.mark.parametrize("name,robot", VARIANTS, ids=[v[0] for v in VARIANTS])
def test_the_compiled_error_map_is_the_numpy_algebra(name, robot):
    """``error_map`` (compiled, one pose at a time) equals the batched numpy formula to
    rounding, with the nominal tensions given or computed; a singular pose is nan."""
    rng = np.random.default_rng(zlib.crc32(name.encode()) + 1)
    p, R = random_poses(robot, 30, rng)
    t = rule_tensions(robot, p, R)[0]
    want = numpy_error_map(robot, p, R, t)
    scale = np.abs(want).max(axis=(1, 2))[:, None, None]
    for got in (error_map(robot, p, R, t), error_map(robot, p, R)):
        np.testing.assert_allclose(got, want, rtol=0, atol=1e-12 * scale.max())
        assert np.all(np.abs(got - want) <= 1e-12 * scale)
    on_anchor = p[:1] + 0.0
    on_anchor[0] = robot.base_anchors[0] - R[0] @ robot.platform_anchors[0]  # cable length 0
    assert np.all(np.isnan(error_map(robot, on_anchor, R[:1])))


@pytest.mark.parametrize("name,robot", VARIANTS, ids=[v[0] for v in VARIANTS])
def test_the_one_pass_accuracy_is_the_error_maps_box_maximum(name, robot):
    """``pose_accuracy``'s compiled pass gives bit for bit ``box_max_norm`` of
    ``error_map``'s rows, and the poses it leaves to those (a singular one: inf) too."""
    rng = np.random.default_rng(zlib.crc32(name.encode()) + 2)
    p, R = random_poses(robot, 30, rng)
    p[7] = robot.base_anchors[0] - R[7] @ robot.platform_anchors[0]  # a cable of length 0
    t = rule_tensions(robot, p, R)[0]
    G = error_map(robot, p, R, t)
    acc = pose_accuracy(robot, p, R=R, tensions=t)
    np.testing.assert_array_equal(acc.position_m, box_max_norm(G[:, :3], robot.length_error))
    np.testing.assert_array_equal(acc.orientation_rad, box_max_norm(G[:, 3:], robot.length_error))
    assert acc.position_m[7] == np.inf and np.isfinite(np.delete(acc.position_m, 7)).all()


# ------------------------------------------------------------ exact against brute force

@pytest.mark.parametrize("name,robot", VARIANTS, ids=[v[0] for v in VARIANTS])
def test_exact_worst_case_equals_brute_force_on_every_shipped_robot(name, robot):
    rng = np.random.default_rng(zlib.crc32(name.encode()))
    p, R = random_poses(robot, 40, rng)
    G = error_map(robot, p, R)
    acc = pose_accuracy(robot, p, R=R)
    e = robot.length_error
    for got, rows in ((acc.position_m, slice(0, 3)), (acc.orientation_rad, slice(3, 6))):
        want = brute_force(G[:, rows], e)
        np.testing.assert_allclose(got, want, rtol=1e-12, atol=0)
        assert np.all(bound(G[:, rows], e) >= got * (1 - 1e-12))


@pytest.mark.parametrize("m", [6, 7, 8, 10, 12])
def test_exact_worst_case_on_random_maps_and_per_cable_errors(m):
    rng = np.random.default_rng(m)
    M = rng.normal(size=(60, 3, m)) * rng.uniform(0.01, 10.0, size=(60, 1, m))
    e = rng.uniform(1e-5, 1e-3, size=m)
    np.testing.assert_allclose(box_max_norm(M, e), brute_force(M, e), rtol=1e-12, atol=0)


def test_sixteen_cables_against_brute_force():
    rng = np.random.default_rng(16)
    M = rng.normal(size=(3, 3, 16))
    np.testing.assert_allclose(box_max_norm(M, 1e-4), brute_force(M, np.full(16, 1e-4)),
                               rtol=1e-12, atol=0)


def test_degenerate_columns_are_exact_or_bounded_above():
    """Zero, parallel, antiparallel and coplanar columns (symmetric robots at symmetric
    poses): exact against brute force, never below it."""
    rng = np.random.default_rng(7)
    M = rng.normal(size=(24, 3, 8))
    M[0:4, :, 1] = 2.0 * M[0:4, :, 0]            # parallel
    M[4:8, :, 2] = -0.5 * M[4:8, :, 3]           # antiparallel
    M[8:12, 2, :] = 0.0                          # every column in one plane (rank 2)
    M[12:16, :, 5] = 0.0                         # a zero column
    M[16:18] = np.outer([1.0, 2.0, 3.0], rng.normal(size=8))  # rank 1
    M[18, :, :] = 0.0                            # all zero
    M[19:24, :, 4] = M[19:24, :, 0] + M[19:24, :, 1]  # a third column in the plane of two
    e = np.full(8, 1e-4)
    want = brute_force(M, e)
    got = box_max_norm(M, e)
    np.testing.assert_allclose(got, want, rtol=1e-12, atol=1e-300)
    assert np.all(got >= want * (1 - 1e-15))


def test_seventeen_cables_exact_or_the_bound_where_degenerate():
    """Above BRUTE_FORCE_MAX_CABLES a degenerate map gets the upper bound (never below the
    exact value); a generic one is still exact."""
    rng = np.random.default_rng(17)
    M = rng.normal(size=(2, 3, 17))
    M[1, :, 3] = 3.0 * M[1, :, 2]  # parallel columns: degenerate
    e = np.full(17, 1e-4)
    want, got = brute_force(M, e), box_max_norm(M, e)
    np.testing.assert_allclose(got[0], want[0], rtol=1e-12)
    assert got[1] >= want[1] and got[1] == pytest.approx(bound(M[1:], e)[0], rel=1e-12)


def test_singular_pose_is_infinitely_inaccurate():
    robot = load_robot(CONFIG / "robot2.yaml")
    # all anchors in one plane with the platform in it: A's moment rows about z-axis vanish
    acc = pose_accuracy(robot, np.array([[0.0, 0.0, 0.0]]), R=np.eye(3)[None])
    assert np.isinf(acc.position_m[0]) and np.isinf(acc.orientation_rad[0])


# ------------------------------------------------------------- the map by finite differences

def _twist(p0, R0, p1, R1):
    """[dp; dw] from (p0, R0) to (p1, R1), dw the rotation vector of R1 R0^T."""
    return np.r_[p1 - p0, Rotation.from_matrix(R1 @ R0.T).as_rotvec()]


def test_six_cable_rigid_map_is_forward_kinematics_of_perturbed_lengths():
    """Rigid six cables: winch j paying out h more moves the platform by G[:, j] h,
    the forward kinematics of lengths L + h e_j (central differences)."""
    robot = dataclasses.replace(load_robot(CONFIG / "robot2.yaml"), cable_stiffness=None)
    p, R = np.array([0.02, -0.01, 0.22]), rotation_tt(np.array([[0.4, 0.5, 0.1]]))[0]
    G = error_map(robot, p[None], R[None])[0]
    L, h = cable_lengths(robot, p, R), 1e-6
    for j in range(6):
        ends = []
        for sign in (1.0, -1.0):
            fk = forward_kinematics(robot, L + sign * h * np.eye(6)[j], p, R)
            assert fk.ok
            ends.append(_twist(p, R, fk.p, fk.R))
        fd = (ends[0] - ends[1]) / (2 * h)
        np.testing.assert_allclose(fd, G[:, j], rtol=1e-6, atol=1e-6 * np.abs(G[:, j]).max())


def _elastic_equilibrium(robot, L0, p, R):
    """The pose (p, R) where cables of unstretched lengths L0 carry the load (J t = w0,
    t = EA (L - L0) / L0, the planner's statics), by Newton with a difference Jacobian."""
    def residual(x):
        q, Q = p + x[:3], rotation_vector_exp(x[3:]) @ R
        d = q + robot.platform_anchors @ Q.T - robot.base_anchors
        L = np.linalg.norm(d, axis=1)
        J = screw_jacobian(robot, (d / L[:, None])[None])[0]
        t = robot.cable_stiffness * (L - L0) / L0
        return J @ t - nominal_wrench(robot, load_point(robot, q[None], Q[None]))[0]

    x = np.zeros(6)
    for _ in range(30):
        r = residual(x)
        Jr = np.column_stack([(residual(x + 1e-7 * e) - residual(x - 1e-7 * e)) / 2e-7
                              for e in np.eye(6)])
        step = np.linalg.solve(Jr, -r)
        x += step
        if np.abs(step).max() < 1e-15:
            break
    assert np.abs(residual(x)).max() < 1e-9
    return p + x[:3], rotation_vector_exp(x[3:]) @ R


@pytest.mark.parametrize("EA,rtol", [(1e3, 1e-2), (1e6, 1e-5)])
def test_eight_cable_elastic_map_is_the_perturbed_equilibrium(EA, rtol):
    """Eight elastic cables at the unstretched lengths that carry the nominal tensions: the
    platform's equilibrium moves by G[:, j] h when L0_j grows by h. The map leaves out the
    geometric stiffness (tensions t against EA), so it agrees to O(t / EA): measured
    0.4 % at EA 1 kN (Robot 2-8's nylon), 4e-6 at 1 MN (1000 times less)."""
    robot = dataclasses.replace(load_robot(CONFIG / "robot2_8.yaml"), cable_stiffness=np.full(8, EA))
    p, R = np.array([0.0, 0.01, 0.25]), rotation_tt(np.array([[0.3, 0.2, 0.0]]))[0]
    assert band_feasibility(robot, p[None], R=R[None]).feasible[0]
    t = rule_tensions(robot, p[None], R[None])[0][0]
    L0 = elastic.unstretched_lengths(robot, cable_lengths(robot, p, R), t)
    p0, R0 = _elastic_equilibrium(robot, L0, p, R)
    np.testing.assert_allclose(_twist(p, R, p0, R0), 0.0, atol=1e-12)  # the planned pose
    G = error_map(robot, p[None], R[None])[0]
    h = 1e-7
    for j in range(8):
        ends = [_twist(p, R, *_elastic_equilibrium(robot, L0 + s * h * np.eye(8)[j], p, R))
                for s in (1.0, -1.0)]
        fd = (ends[0] - ends[1]) / (2 * h)
        for rows in (slice(0, 3), slice(3, 6)):
            err = np.linalg.norm(fd[rows] - G[rows, j]) / np.linalg.norm(G[rows, j])
            assert err < rtol, (j, err)


def test_six_cables_elastic_and_rigid_agree():
    """For six cables dx = A^-T dl whatever the stiffness."""
    robot = load_robot(CONFIG / "robot1.yaml")
    p, R = random_poses(robot, 10, np.random.default_rng(3))
    np.testing.assert_array_equal(
        error_map(robot, p, R), error_map(dataclasses.replace(robot, cable_stiffness=None), p, R))


# --------------------------------------------------------------------------- the planner

SPHERE = SphereTask(center=(0.0, 0.0, 0.306), radius=0.13)
HUMP_START, HUMP_GOAL = (0.6, 1.0), (2.6, 1.0)  # either side of the hump between two tongues


def _plan(settings, start=HUMP_START, goal=HUMP_GOAL):
    robot = load_robot(CONFIG / "robot2.yaml")
    planner = Planner(robot, SPHERE, settings)
    ends = [Pose(*(a[0] for a in SPHERE.pose(np.array([y])))) for y in (start, goal)]
    return robot, planner.plan(*ends)


def _dense_accuracy(robot, path, per_segment=40):
    """The accuracy at ``per_segment`` poses of each motion between waypoints (position
    linear, orientation slerp: what was checked), by scipy's Slerp."""
    s = np.linspace(0.0, 1.0, per_segment)
    ps, Rs = [], []
    for k in range(len(path) - 1):
        ps.append(path.p[k] + s[:, None] * (path.p[k + 1] - path.p[k]))
        slerp = Slerp([0.0, 1.0], Rotation.from_quat(path.quaternion[k:k + 2]))
        Rs.append(slerp(s).as_matrix())
    return pose_accuracy(robot, np.concatenate(ps), R=np.concatenate(Rs))


@pytest.mark.parametrize("setting,limit,field", [
    ("accuracy_position_m", 0.24e-3, "position"),        # the shortest path: 0.27 mm (README)
    ("accuracy_orientation_rad", 4.4e-3, "orientation"),  # the shortest path: 4.5 mrad
])
def test_plan_keeps_the_limit_at_every_dense_sample(setting, limit, field):
    attr, key = {"position": ("position_m", "position_error_m"),
                 "orientation": ("orientation_rad", "orientation_error_rad")}[field]
    robot, free = _plan(PlannerSettings())
    assert free.success
    assert getattr(_dense_accuracy(robot, free.path), attr).max() > limit  # the limit binds
    robot, res = _plan(PlannerSettings(**{setting: limit}))
    assert res.success, res.message
    assert getattr(_dense_accuracy(robot, res.path), attr).max() <= limit
    doc = plan_document(res, robot)  # the plan JSON carries it per waypoint
    errors = np.array([w[key] for w in doc["path"]])
    assert errors.max() <= limit and len(errors) == len(res.path)
    np.testing.assert_allclose(errors, getattr(pose_accuracy(
        robot, res.path.p, R=rotation_from_quaternion(res.path.quaternion)), attr), rtol=1e-12)
    assert all("position_error_m" in w and "orientation_error_rad" in w for w in doc["path"])


def test_dense_motion_check_keeps_the_limit():
    """A wrench-feasible motion over the hump at alpha2 = 1.2 peaks at 0.244 mm: invalid
    under a 0.23 mm limit, its first unsafe point bound by accuracy_position; 0.1 rad higher
    it peaks at 0.208 mm and is valid."""
    from cdh_planner.pipeline.validity import Validity
    robot = load_robot(CONFIG / "robot2.yaml")
    free = Validity(robot, SPHERE, 1e-3)
    limited = Validity(robot, SPHERE, 1e-3, accuracy=(0.23e-3, 0.0))
    low, high = np.array([[0.6, 1.2], [2.6, 1.2]]), np.array([[0.6, 1.3], [2.6, 1.3]])
    assert free.motion(*low) and limited.pose(low).all()
    assert not limited.motion(*low) and limited.motion(*high)
    seg = check_path(robot, limited.direct_motion(low), feasibility=limited.feasibility)[0]
    assert not seg.feasible and seg.first_unsafe.binding == "accuracy_position"
    err = pose_accuracy(robot, seg.first_unsafe.position[None],
                        R=rotation_from_quaternion(seg.first_unsafe.quaternion)[None]).position_m[0]
    assert err == pytest.approx(0.23e-3 * (1 - seg.first_unsafe.margin), rel=1e-9)


def test_tight_limit_is_no_path_with_the_reason():
    _, res = _plan(PlannerSettings(accuracy_position_m=0.2e-3))
    assert not res.success and res.reason == Status.START_INFEASIBLE
    assert "accuracy" in res.message and "planner.accuracy_position_m (0.2 mm)" in res.message
    _, res = _plan(PlannerSettings(accuracy_orientation_rad=1e-3))
    assert not res.success and "planner.accuracy_orientation_rad" in res.message


def test_limits_off_without_length_error_and_refused_when_set():
    robot = dataclasses.replace(load_robot(CONFIG / "robot2.yaml"), length_error=None)
    Planner(robot, SPHERE, PlannerSettings())  # off: fine
    with pytest.raises(InputError, match=r"planner\.accuracy_position_m.*robot\.length_error") as e:
        Planner(robot, SPHERE, PlannerSettings(accuracy_position_m=1e-3))
    assert "\n" not in str(e.value)
    assert plan_document(_plan_result_stub(), robot)["path"] == []


def _plan_result_stub():
    from cdh_planner.planner import PlanResult
    return PlanResult(False, Status.NO_PATH, "", "astar", 2, 2, 0, 0.0, float("nan"))


@pytest.mark.parametrize("value", ["-1", "nan", "2"])
def test_bad_setting_refused_with_one_line(tmp_path, capsys, value):
    problem = CONFIG / "problems" / "robot2_q2_q3.yaml"
    assert cli.main(["plan", str(problem), "--accuracy-position", value, "--quiet"]) == 2
    err = capsys.readouterr().err.strip()
    assert "--accuracy-position" in err and len(err.splitlines()) == 1


def test_problem_file_setting_refused_for_a_robot_without_length_error(tmp_path, capsys):
    robot_file = tmp_path / "r.yaml"
    robot_file.write_text("\n".join(line for line in (CONFIG / "robot2.yaml").read_text().splitlines()
                                    if "length_error" not in line))
    problem = tmp_path / "p.yaml"
    problem.write_text(f"robot: {robot_file}\ntask: {{type: sphere, center: [0, 0, 0.306], "
                       "radius: 0.13}\nstart: {lambda: [0.55, 0.75]}\ngoal: {lambda: [2.63, 0.75]}\n"
                       "planner: {accuracy_orientation_rad: 0.01}\n")
    assert cli.main(["plan", str(problem), "--quiet"]) == 2
    err = capsys.readouterr().err.strip()
    assert "planner.accuracy_orientation_rad" in err and "robot.length_error" in err
    assert len(err.splitlines()) == 1


# ------------------------------------------------------------------ verify, slice, diagnostics

def test_verify_json_keys(tmp_path, capsys):
    poses = tmp_path / "poses.json"
    poses.write_text(json.dumps([{"position": [0.0811, 0.0497, 0.2174], "tau": [-2.59159, 0.820796, 0]},
                                 {"position": [0.0, 0.0, 0.25], "quaternion": [0, 0, 0, 1]}]))
    out = tmp_path / "v.json"
    cli.main(["verify", str(CONFIG / "robot2.yaml"), str(poses), "--json", str(out)])
    text = capsys.readouterr().out
    assert "accuracy: position error" in text
    doc = json.loads(out.read_text())
    robot = load_robot(CONFIG / "robot2.yaml")
    p = np.array([row["position"] for row in doc["poses"]])
    acc = pose_accuracy(robot, p, R=rotation_from_quaternion(np.array([r["quaternion"] for r in doc["poses"]])))
    np.testing.assert_allclose([r["position_error_m"] for r in doc["poses"]], acc.position_m, rtol=1e-12)
    np.testing.assert_allclose([r["orientation_error_rad"] for r in doc["poses"]], acc.orientation_rad,
                               rtol=1e-12)
    # without length_error: absent, and said so
    plain = tmp_path / "plain.yaml"
    plain.write_text("\n".join(line for line in (CONFIG / "robot2.yaml").read_text().splitlines()
                               if "length_error" not in line))
    cli.main(["verify", str(plain), str(poses), "--json", str(out)])
    assert "accuracy: not given" in capsys.readouterr().out
    assert all("position_error_m" not in r for r in json.loads(out.read_text())["poses"])


def test_slice_colours_feasible_poses_beyond_the_limit():
    robot = load_robot(CONFIG / "robot2.yaml")
    view = SliceView(task=SPHERE, axes=("alpha1", "alpha2"), ranges=((0.3, 1.0), (0.7, 1.2)))
    limits = AccuracyLimits(0.3e-3, 0.0)
    plain = compute_slice(robot, view, resolution=30)
    grid = compute_slice(robot, view, resolution=30, accuracy=limits)
    A, B = np.meshgrid(grid.xs, grid.ys)
    p, tau = SPHERE.pose(view.coords(A, B))
    err = pose_accuracy(robot, p, tau).position_m.reshape(A.shape)
    was = plain.classes == FEASIBLE
    np.testing.assert_array_equal(grid.classes == INACCURATE, was & (err > 0.3e-3))
    np.testing.assert_array_equal(grid.classes[~was], plain.classes[~was])
    assert (grid.classes == INACCURATE).any() and (grid.classes == FEASIBLE).any()


def test_slice_cli_refuses_a_limit_without_length_error(tmp_path, capsys):
    plain = tmp_path / "plain.yaml"
    plain.write_text("\n".join(line for line in (CONFIG / "robot2.yaml").read_text().splitlines()
                               if "length_error" not in line))
    rc = cli.main(["slice", str(plain), "--sphere", "0,0,0.306,0.13", "--accuracy-position",
                   "0.3mm", "--resolution", "10", "-o", str(tmp_path / "s.png")])
    err = capsys.readouterr().err.strip()
    assert rc == 2 and "--accuracy-position" in err and "robot.length_error" in err


def test_diagnostics_values():
    def values(h):
        return {kv.key: kv.value for kv in health_status(h, "n").values}
    assert values(Health(state="active"))["position_error_m"] == "not given"
    assert values(Health(state="active", accuracy_given=True))["orientation_error_rad"] == "none"
    v = values(Health(state="active", accuracy_given=True, accuracy=(3.5e-4, 6.3e-3)))
    assert float(v["position_error_m"]) == 3.5e-4 and float(v["orientation_error_rad"]) == 6.3e-3
