"""``verify`` evaluates each pose once: the dense motion check takes the poses' own margins
for its samples at s = 0 and 1 (``check_motion(waypoints=...)``), which are then the poses
bit for bit (``SlerpPath(exact_ends=True)``), and evaluates only the interior samples."""
import json
from types import SimpleNamespace

import numpy as np
import pytest

from cdh_planner import cli
from cdh_planner.commands import verify
from cdh_planner.model.pose import quaternion_from_tau, rotation_from_quaternion
from cdh_planner.model.robot import load_robot
from cdh_planner.parsing.poses import load_poses
from cdh_planner.scene.margin import combine
from cdh_planner.scene.schema import load_scene
from cdh_planner.trajectory import path_check as pc
from cdh_planner.wrench import wrench_feasibility

from conftest import CONFIG, REPO

REFERENCE = REPO / "test" / "verify_reference"
# (robot, poses, scene file or None): 6 cables with and without a scene, 8 cables
CASES = {"robot2": ("robot2", REFERENCE / "robot2_poses.json", None),
         "robot2_ball": ("robot2", REFERENCE / "robot2_poses.json", CONFIG / "scenes/robot2_ball.yaml"),
         "cogiro": ("cogiro", REFERENCE / "cogiro_poses.json", None)}


def _case(name):
    """(robot, poses, collision model or None) of a CASES entry."""
    robot_name, poses_file, scene_file = CASES[name]
    robot = load_robot(CONFIG / f"{robot_name}.yaml")
    collision = None
    if scene_file is not None:
        from cdh_planner.scene.collision import CollisionModel
        collision = CollisionModel(robot, load_scene(scene_file, robot))
    return robot, load_poses(poses_file), collision


def _pose_margins(robot, poses, collision):
    """What verify computes for the poses: wrench_feasibility, combined with collision."""
    f = wrench_feasibility(robot, poses.positions, R=poses.rotations)
    margin, binding = combine(f.margin, f.binding, collision, poses.positions, poses.rotations)
    return SimpleNamespace(margin=margin, binding=binding)


def _walk(n=60, step_m=3e-3, step_rad=5e-3, seed=1):
    """A random walk of n poses (positions (n, 3) m, quaternions (n, 4)) near the middle of
    Robot 2's workspace, steps of a few samples at the default sampling."""
    rng = np.random.default_rng(seed)
    p = np.array([0.0, 0.0, 0.3]) + np.cumsum(rng.normal(0, step_m / np.sqrt(3), (n, 3)), axis=0)
    tau = np.array([0.0, 0.1, 0.0]) + np.cumsum(rng.normal(0, step_rad, (n, 3)), axis=0)
    return p, quaternion_from_tau(tau)


def test_exact_ends_are_the_waypoints_and_the_interior_unchanged():
    p, q = _walk(20)
    plain, exact = pc.SlerpPath(p, q), pc.SlerpPath(p, q, exact_ends=True)
    seg = np.repeat(np.arange(19), 4)
    s = np.tile([0.0, 0.25, 0.7, 1.0], 19)
    (pe, Re), (pp, Rp) = exact(seg, s), plain(seg, s)
    k = seg + (s == 1.0)
    end = (s == 0.0) | (s == 1.0)
    assert np.array_equal(pe[end], p[k[end]])
    assert np.array_equal(Re[end], rotation_from_quaternion(q)[k[end]])  # verify's rotations
    assert np.array_equal(pe[~end], pp[~end]) and np.array_equal(Re[~end], Rp[~end])
    # the formula's ends are the waypoints to rounding only
    np.testing.assert_allclose(pe, pp, rtol=0, atol=1e-15)
    np.testing.assert_allclose(Re, Rp, rtol=0, atol=1e-14)


@pytest.mark.parametrize("name", CASES)
def test_end_samples_take_exactly_what_their_evaluation_gives(name):
    # The reused value is what evaluating the end sample (the waypoint) gives, bit for bit:
    # verify's wrench_feasibility + combine at the poses == check_path's wrench_margin +
    # combine at the path's ends.
    robot, poses, collision = _case(name)
    n = len(poses)
    path = pc.SlerpPath(poses.positions, poses.quaternions, exact_ends=True)
    seg = np.r_[np.arange(n - 1), np.arange(n - 1)]
    s = np.r_[np.zeros(n - 1), np.ones(n - 1)]
    known = _pose_margins(robot, poses, collision)
    reused = pc._Samples(robot, path, collision, waypoints=known).evaluate(seg, s)
    fresh = pc._Samples(robot, path, collision).evaluate(seg, s)
    assert np.array_equal(reused[0], fresh[0])
    assert list(reused[1]) == list(fresh[1])
    k = seg + (s == 1.0)
    assert np.array_equal(reused[0], np.where(np.isnan(known.margin), -np.inf, known.margin)[k])


@pytest.mark.parametrize("name", [*CASES, "walk"])
def test_segments_equal_those_of_the_per_sample_evaluation(name):
    if name == "walk":
        robot, collision = load_robot(CONFIG / "robot2.yaml"), None
        p, q = _walk()
        poses = SimpleNamespace(positions=p, quaternions=q, rotations=rotation_from_quaternion(q))
    else:
        robot, poses, collision = _case(name)
    known = _pose_margins(robot, poses, collision)
    old = pc.check_motion(robot, poses.positions, poses.quaternions, collision=collision)
    new = pc.check_motion(robot, poses.positions, poses.quaternions, collision=collision,
                          waypoints=known)
    assert np.array_equal(new.feasible, old.feasible)
    assert np.array_equal(new.samples, old.samples)
    assert np.array_equal(new.unresolved, old.unresolved)
    assert np.array_equal(new.unsafe_index, old.unsafe_index)
    for a, b in ((new.worst, old.worst), (new.unsafe, old.unsafe)):
        assert np.array_equal(a.s, b.s) and a.binding == b.binding
        np.testing.assert_allclose(a.margin, b.margin, rtol=0, atol=1e-12)
        np.testing.assert_allclose(a.position, b.position, rtol=0, atol=1e-12)
        np.testing.assert_allclose(a.quaternion, b.quaternion, rtol=0, atol=1e-12)
    # a worst point at an end is the pose: its margin is the pose's, bit for bit
    at = np.flatnonzero((new.worst.s == 0.0) | (new.worst.s == 1.0))
    assert at.size
    k = at + (new.worst.s[at] == 1.0)
    assert np.array_equal(new.worst.margin[at], known.margin[k])


def test_verify_evaluates_each_pose_once(tmp_path, monkeypatch):
    # N poses evaluated by verify's pose check, and by the motion check only the interior
    # samples: every segment feasible (no bisection), so sum(samples) - 2 (N - 1) of them.
    p, q = _walk()
    counts = {"poses": 0, "samples": 0}

    def counting(key, test):
        def test_(robot, p, tau=None, R=None):
            counts[key] += len(p)
            return test(robot, p, tau=tau, R=R)
        return test_

    monkeypatch.setattr(verify, "wrench_feasibility", counting("poses", verify.wrench_feasibility))
    monkeypatch.setattr(pc, "wrench_margin", counting("samples", pc.wrench_margin))
    poses_file, out = tmp_path / "poses.json", tmp_path / "out.json"
    poses_file.write_text(json.dumps([{"position": a, "quaternion": b}
                                      for a, b in zip(p.tolist(), q.tolist())]))
    assert cli.main(["verify", str(CONFIG / "robot2.yaml"), str(poses_file), "--json", str(out)]) == 0
    segments = json.loads(out.read_text())["segments"]
    n = len(p)
    interior = sum(seg["samples"] for seg in segments) - 2 * (n - 1)
    assert interior > 0
    assert counts == {"poses": n, "samples": interior}


def test_the_worst_sample_of_a_segment_is_the_first_least_as_sorting_finds_it():
    """``_least_in_segments`` against a sort by (segment, margin, index): margins with many
    ties, -inf (singular samples), 0.0 and -0.0, segments of 2 to 9 samples."""
    rng = np.random.default_rng(5)
    for _ in range(200):
        sizes = rng.integers(2, 10, rng.integers(1, 40))
        seg = np.repeat(np.arange(len(sizes)), sizes)
        margin = rng.choice([-np.inf, -0.5, -0.0, 0.0, 0.25, 0.5, 1.0], seg.size)
        bounds = np.searchsorted(seg, np.arange(len(sizes) + 1))
        order = np.lexsort((np.arange(seg.size), margin, seg))
        assert np.array_equal(pc._least_in_segments(margin, bounds), order[bounds[:-1]])


def test_samples_in_order_are_recognised():
    """``_Samples.add`` keeps a first batch as given only when it is in (segment, s) order
    (the initial grid); anything else is sorted."""
    seg, s = pc._initial_grid(pc.SlerpPath(*_walk(12)), 1e-3, np.deg2rad(0.2))
    assert pc._in_order(seg, s)
    assert not pc._in_order(seg[::-1], s[::-1])
    assert not pc._in_order(np.array([0, 0]), np.array([0.5, 0.5]))  # a tie: lexsort decides
    assert not pc._in_order(np.array([1, 0]), np.array([0.0, 1.0]))
