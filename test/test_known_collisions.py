"""Poses a probe found in collision (pipeline.validity.KnownCollisions): the poses around
one whose binding cable's platform anchor stays within d_min - d are in collision too
(each point of a cable moves no more than its platform anchor), so a direct motion
through them is refused without a probe, and the search does not probe again, chart after
chart, a goal behind the obstacle that the last probe hit. Distances checked without
coal (a sphere against a cable: point-segment less both radii)."""

import dataclasses

import numpy as np
from scipy.spatial.transform import Rotation

from cdh_planner.model.pose import quaternion_from_tau
from cdh_planner.pipeline.validity import KnownCollisions, Validity
from cdh_planner.planner import Planner
from cdh_planner.scene.margin import COLLISION_UNIT_M
from cdh_planner.scene.schema import scene_from_dict

from test_scene_distances import point_segment
from test_scene_domain import BALL, PROBLEM, R_CABLE, ROBOT, sphere_distances

FLOOR = PROBLEM.settings.margin_floor
D_MIN = PROBLEM.scene.clearance + FLOOR * COLLISION_UNIT_M  # m: the least valid distance


def straight(n):
    """n poses (p (n, 3), R (n, 3, 3)) of the start -> goal motion, which hits the ball."""
    s = np.linspace(0.0, 1.0, n)[:, None]
    p = PROBLEM.start.p + s * (PROBLEM.goal.p - PROBLEM.start.p)
    q = quaternion_from_tau(np.array([PROBLEM.start.tau, PROBLEM.goal.tau]))
    key = Rotation.from_quat(q)
    rel = (key[0].inv() * key[1]).as_rotvec()
    R = (key[0] * Rotation.from_rotvec(s * rel)).as_matrix()
    return p, R


def validity():
    return Validity(ROBOT, PROBLEM.task, FLOOR, PROBLEM.scene)


def test_binding_cables_name_the_cable_on_the_ball_and_its_exact_distance():
    v = validity()
    p, R = straight(41)
    d, cable = v.collision.binding_cables(p, R)
    exact = sphere_distances(BALL.position, BALL.radius, p, R)
    hit = cable >= 0
    assert hit.any() and (exact[hit] < 0).any()
    assert np.allclose(d[hit], exact[hit], atol=1e-12)
    for k in np.flatnonzero(hit):  # the named cable is the one at that distance
        i = cable[k]
        B = p[k] + R[k] @ ROBOT.platform_anchors[i]
        assert abs(point_segment(BALL.position, ROBOT.base_anchors[i], B) - BALL.radius
                   - R_CABLE - d[k]) < 1e-12


def test_every_pose_within_a_known_collision_is_in_collision():
    """The bound: random poses around the deepest pose of the straight motion; each one
    the known collisions call crossed is closer to the ball than d_min (exactly), and
    some poses are crossed, some not."""
    v = validity()
    p, R = straight(41)
    known = KnownCollisions(ROBOT, v.collision, D_MIN)
    known.add(p, R)
    assert len(known.radius) == 1 and known.radius[0] > D_MIN
    k = int(np.argmin(sphere_distances(BALL.position, BALL.radius, p, R)))
    rng = np.random.default_rng(3)
    crossed = 0
    for _ in range(300):
        scale = rng.uniform(0.0, 0.03)
        pq = p[k] + scale * rng.standard_normal(3)
        Rq = Rotation.from_rotvec(scale * 3 * rng.standard_normal(3)).as_matrix() @ R[k]
        if known.crossed(pq[None], Rq[None]):
            crossed += 1
            assert sphere_distances(BALL.position, BALL.radius, pq[None], Rq[None])[0] < D_MIN
    assert 10 < crossed < 290


def test_a_known_collision_needs_a_cable_on_an_obstacle_below_d_min():
    """Poses clear of the ball (or failing for another reason) are not remembered."""
    v = validity()
    p, R = straight(41)
    clear = sphere_distances(BALL.position, BALL.radius, p, R) > D_MIN
    known = KnownCollisions(ROBOT, v.collision, D_MIN)
    known.add(p[clear], R[clear])
    assert len(known.radius) == 0 and not known.crossed(p, R)
    empty = Validity(ROBOT, PROBLEM.task, FLOOR, scene_from_dict({"obstacles": []}))
    known = KnownCollisions(ROBOT, empty.collision, D_MIN)
    known.add(p, R)  # cable pairs bind: nothing to remember
    assert len(known.radius) == 0
    assert Validity(ROBOT, PROBLEM.task, FLOOR).known is None  # no scene, nothing kept


def test_a_motion_through_a_known_collision_is_refused_without_a_probe():
    """The straight motion is probed once and fails; a motion to the same goal from a
    start a few mm away passes the same place and is refused with no probe."""
    v = validity()
    probes = []
    probe = v.probe
    v.probe = lambda *a, **k: probes.append(1) or probe(*a, **k)
    ys, yg = (v.task.coords(e.p[None], e.tau[None])[0] for e in (PROBLEM.start, PROBLEM.goal))
    assert not v.motion(ys, yg)
    assert len(probes) == 1 and len(v.known.radius) == 1
    nearby = ys.copy()
    nearby[:3] += [0.002, -0.001, 0.001]
    assert not v.motion(nearby, yg)
    assert len(probes) == 1


def test_the_search_probes_a_blocked_goal_fewer_times_with_the_same_route():
    """The ball problem: the planner's search tries direct motions from its new charts to
    the far end; behind the ball most are refused without a probe. Without the known
    collisions (the same search: a refused motion was invalid anyway) each one is probed."""
    def planned(remember):
        s = dataclasses.replace(PROBLEM.settings, timeout_s=60.0)
        planner = Planner(ROBOT, PROBLEM.task, s, scene=PROBLEM.scene)
        v = planner.validity
        if not remember:
            v.known = None
        calls = {"motion": 0, "probe": 0}
        motion, probe = v.motion, v.probe

        def counted_motion(*a):
            calls["motion"] += 1
            return motion(*a)

        def counted_probe(*a, **k):
            calls["probe"] += 1
            return probe(*a, **k)
        v.motion, v.probe = counted_motion, counted_probe
        result = planner.plan(PROBLEM.start, PROBLEM.goal)
        assert result.success, result.message
        return result, calls, len(planner.atlas.charts)

    with_known, calls, charts = planned(True)
    without, calls_without, charts_without = planned(False)
    assert charts == charts_without and len(with_known.path) == len(without.path)
    assert np.array_equal(with_known.path.p, without.path.p)
    assert calls["motion"] == calls_without["motion"] > 1
    assert calls["probe"] < calls_without["probe"]
