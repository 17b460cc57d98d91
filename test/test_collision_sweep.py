"""The executed check's collision test along a motion (``CollisionModel.blocked_along``):
exact margins at every SWEEP_STRIDE-th sample, and between them only where the sweep bound
(``sweep_steps``: how far any checked distance can change from one pose to the next)
cannot clear a sample. The bound is checked on every pair's distance of a random walk
(a platform shape, shared platform anchors, a sphere and a box), and the answers against
``margins(...) < 0`` at every pose of motions through obstacles."""

import numpy as np
import pytest

from cdh_planner.ports import Rotation
from cdh_planner.scene import collision as C
from cdh_planner.scene.collision import CollisionModel
from cdh_planner.scene.schema import scene_from_dict

from test_known_collisions import straight
from test_scene_domain import PROBLEM, ROBOT

OBSTACLES = [{"id": "ball", "type": "sphere", "radius": 0.01,
              "position": [0.1551, -0.0219, 0.1177]},
             {"id": "block", "type": "box", "size": [0.03, 0.02, 0.04],
              "position": [0.02, 0.05, 0.30], "quaternion": [0.1, 0.5, 0.3, 0.8062257748298549]}]
PLATFORM = {"type": "box", "size": [0.14, 0.14, 0.01], "position": [0.0, 0.0, 0.005]}


def model(platform=True):
    scene = {"cable_radius": 0.001, "obstacles": OBSTACLES}
    if platform:
        scene["platform"] = PLATFORM
    return CollisionModel(ROBOT, scene_from_dict(scene, ROBOT))


def walk(n, step, seed):
    """n poses of a random walk around the straight motion's middle (m, rad per pose)."""
    rng = np.random.default_rng(seed)
    p0, R0 = straight(3)
    p = p0[1] + np.cumsum(rng.normal(scale=step, size=(n, 3)), axis=0)
    turn = Rotation.from_rotvec(np.cumsum(rng.normal(scale=step * 5, size=(n, 3)), axis=0))
    return p, (turn * Rotation.from_matrix(R0[1])).as_matrix()


@pytest.mark.parametrize("platform", [True, False])
def test_no_checked_distance_changes_more_than_the_sweep_step(platform):
    """Between consecutive poses every pair's distance (cable-cable with the shared anchors'
    exemption, cable-obstacle, platform-obstacle, cable-platform) changes by no more than
    the step (separated pairs: distances, not penetration depths)."""
    cm = model(platform)
    p, R = walk(120, 0.004, 1)
    steps = cm.sweep_steps(p, R)
    d = np.array([[x[3] for x in cm.distances(p[k], R[k])] for k in range(len(p))])
    change = np.abs(np.diff(d, axis=0))
    apart = (d[:-1] > 0) & (d[1:] > 0)
    assert apart.mean() > 0.8 and np.all(np.isfinite(steps))
    assert np.all(change[apart] <= steps[:, None].repeat(d.shape[1], 1)[apart] + 1e-9)
    assert np.max(change[apart] / steps[:, None].repeat(d.shape[1], 1)[apart]) > 0.05  # not vacuous


@pytest.mark.parametrize("n", [2, 3, 40, 3000])
@pytest.mark.parametrize("platform", [True, False])
def test_blocked_along_a_motion_is_every_poses_own_margin_below_zero(n, platform, monkeypatch):
    """Through the ball (the straight motion) and a walk: the same answer as every pose's
    exact margin, pose by pose, with fewer exact checks on a dense motion."""
    cm = model(platform)
    for smooth, (p, R) in ((True, straight(n)), (False, walk(n, 0.0005, 2))):
        expected = cm.margins(p, R)[0] < 0
        rows = []
        margins = CollisionModel.margins_only
        monkeypatch.setattr(CollisionModel, "margins_only",
                            lambda self, p, R: rows.append(len(p)) or margins(self, p, R))
        got = cm.blocked_along(p, R)
        monkeypatch.undo()
        assert np.array_equal(got, expected)
        assert sum(rows) >= min(n, 2)  # it asked the model
        if n == 3000 and smooth and not platform:  # (the platform box's edges pass within
            assert sum(rows) < n / 2                # mm of the cables: most poses checked)
    assert (cm.margins(*straight(3000))[0] < 0).any()  # it does hit the ball


def test_a_pose_that_cannot_be_bounded_is_checked():
    """No positive bound on the cable lengths (a pose at a base anchor): every step is inf,
    every pose checked exactly."""
    cm = model()
    p, R = straight(40)
    p[5] = ROBOT.base_anchors[0]
    assert np.all(np.isinf(cm.sweep_steps(p, R)))
    assert np.array_equal(cm.blocked_along(p, R), cm.margins(p, R)[0] < 0)


def test_the_stride_and_slack_are_what_the_docstring_says():
    assert C.SWEEP_STRIDE >= 2 and 1e-8 <= C.SWEEP_SLACK_M <= 1e-5


@pytest.mark.parametrize("floor", [0.0, 0.004, "wrench"])
@pytest.mark.parametrize("platform", [True, False])
def test_margins_along_are_exact_wherever_they_may_be_below_the_floor(floor, platform):
    """``margins_along``: ``margins``'s numbers and bindings where the exact margin is below
    floor + SWEEP_SLACK_M; elsewhere a true lower bound of the margin, at least the slack
    above the floor (so that the least of it and the floor is decided without it)."""
    cm = model(platform)
    for p, R in (straight(400), walk(400, 0.0005, 3)):
        exact, exact_binding = cm.margins(p, R)
        f = (np.random.default_rng(4).uniform(0.0, 0.01, len(p)) if floor == "wrench"
             else np.full(len(p), floor))
        got, binding = cm.margins_along(p, R, f)
        same = got == exact
        assert np.all(same | (got - f >= C.SWEEP_SLACK_M))  # a bound clear of the floor...
        assert np.all(got <= exact)                          # ... below the true margin
        assert np.all(same[exact < f + C.SWEEP_SLACK_M])
        assert list(binding[same]) == list(exact_binding[same])
        assert np.all(binding[~same] == None)  # noqa: E711  (elementwise)


@pytest.mark.parametrize("platform", [True, False])
def test_combine_along_a_motion_is_combine(platform):
    """``combine(..., motion=True)`` (collision margins only where they may be the lesser)
    gives ``combine``'s margins and bindings, bit for bit, wherever the wrench margins lie
    (some below the collision margins, some above)."""
    from cdh_planner.scene.margin import combine
    cm = model(platform)
    for p, R in (straight(500), walk(500, 0.0005, 5)):
        wrench = np.random.default_rng(6).uniform(-0.05, 0.3, len(p))
        wrench[7] = -np.inf  # singular
        names = np.array(["tension_max[2]"] * len(p), dtype=object)
        m0, b0 = combine(wrench, names, cm, p, R)
        m1, b1 = combine(wrench, names, cm, p, R, motion=True)
        assert np.array_equal(m0, m1) and list(b0) == list(b1)
        assert 0 < np.sum(b0 == "tension_max[2]") < len(p)  # both kinds bind
