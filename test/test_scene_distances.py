"""The scene's collision distances against computations that do not use coal:
closed-form capsule-sphere, segment-segment (a bounded least-squares problem solved by
scipy), point-box and point-cylinder distances sampled along each cable, and the
platform's box against spheres in closed form. Random Robot 2 poses, every obstacle type
(meshes: a box written to STL). Also: the pruned least distance equals the least of all
pairs, and the shared-anchor exemption is what schema.py says it is."""

import math

import numpy as np
import pytest
from scipy.optimize import lsq_linear
from scipy.spatial.transform import Rotation

from cdh_planner.model.robot import load_robot
from cdh_planner.scene.collision import CollisionModel
from cdh_planner.scene.schema import scene_from_dict

from conftest import CONFIG

ROBOT2 = load_robot(CONFIG / "robot2.yaml")
R_CABLE = 0.002
N_SAMPLES = 4001  # points along a cable: sampled distances are within length / 8000 above


def random_pose(rng):
    p = np.array([0.0, 0.0, 0.40]) + rng.uniform(-0.06, 0.06, 3)
    R = Rotation.from_rotvec(rng.uniform(-0.3, 0.3, 3)).as_matrix()
    return p, R


def platform_anchors(robot, p, R):
    return p + robot.platform_anchors @ R.T


def random_quaternion(rng):
    return Rotation.random(random_state=rng).as_quat().tolist()


def near_cable_point(rng, robot, p, R, spread):
    """A point near a random cable of pose (p, R): obstacles placed there are sometimes
    hit and sometimes missed."""
    i = rng.integers(len(robot.base_anchors))
    a, b = robot.base_anchors[i], platform_anchors(robot, p, R)[i]
    return (a + rng.uniform(0.2, 0.8) * (b - a) + rng.uniform(-spread, spread, 3)).tolist()


# ----------------------------------------------------------------- independent distances

def point_segment(c, a, b):
    d = b - a
    t = np.clip(np.dot(c - a, d) / np.dot(d, d), 0.0, 1.0)
    return float(np.linalg.norm(a + t * d - c))


def segment_segment(p0, p1, q0, q1):
    """min |p0 + s (p1 - p0) - q0 - t (q1 - q0)| over s, t in [0, 1]: bounded least squares."""
    M = np.column_stack([p1 - p0, -(q1 - q0)])
    sol = lsq_linear(M, q0 - p0, bounds=(0.0, 1.0), tol=1e-14, lsmr_tol="auto")
    return float(np.linalg.norm(M @ sol.x - (q0 - p0)))


def box_signed(points, centre, R, size):
    """Signed distance (m) of points (n, 3) to a box (centre, rotation R, full edges)."""
    q = np.abs((points - centre) @ R) - 0.5 * np.asarray(size)
    outside = np.linalg.norm(np.maximum(q, 0.0), axis=1)
    return outside + np.minimum(q.max(axis=1), 0.0)


def cylinder_signed(points, centre, R, radius, height):
    local = (points - centre) @ R
    q = np.column_stack([np.hypot(local[:, 0], local[:, 1]) - radius,
                         np.abs(local[:, 2]) - 0.5 * height])
    return np.linalg.norm(np.maximum(q, 0.0), axis=1) + np.minimum(q.max(axis=1), 0.0)


def sampled_capsule(a, b, signed, r):
    """Least signed distance of the capsule a..b (radius r), the solid's signed distance
    ``signed`` sampled at N_SAMPLES points of the axis; and the sampling's error bound."""
    t = np.linspace(0.0, 1.0, N_SAMPLES)[:, None]
    d = float(np.min(signed(a + t * (b - a)))) - r
    return d, 0.5 * float(np.linalg.norm(b - a)) / (N_SAMPLES - 1)


def model(obstacles, platform=None, radius=R_CABLE, robot=ROBOT2, **extra):
    d = {"cable_radius": radius, "obstacles": obstacles, **extra}
    if platform:
        d["platform"] = platform
    return CollisionModel(robot, scene_from_dict(d))


def cable_obstacle_distances(cm, p, R):
    return {(o, c[0]): d for kind, o, c, d in cm.distances(p, R) if kind == "cable-obstacle"}


# ----------------------------------------------------------------- tests

def test_capsule_sphere_matches_the_closed_form_at_random_poses():
    rng = np.random.default_rng(1)
    signs = set()
    for _ in range(20):
        p, R = random_pose(rng)
        spheres = [{"id": f"s{k}", "type": "sphere", "radius": float(rng.uniform(0.003, 0.03)),
                    "position": near_cable_point(rng, ROBOT2, p, R, 0.03)} for k in range(5)]
        cm = model(spheres)
        Bw = platform_anchors(ROBOT2, p, R)
        for (oid, i), d in cable_obstacle_distances(cm, p, R).items():
            s = spheres[int(oid[1:])]
            exact = point_segment(np.array(s["position"]), ROBOT2.base_anchors[i], Bw[i]) \
                - s["radius"] - R_CABLE
            assert d == pytest.approx(exact, abs=1e-9)
            signs.add(exact > 0)
    assert signs == {True, False}  # both hits and misses were tried


@pytest.mark.parametrize("kind", ["box", "cylinder", "mesh"])
def test_capsule_box_cylinder_mesh_match_sampled_distances(kind, tmp_path):
    trimesh = pytest.importorskip("trimesh")
    rng = np.random.default_rng({"box": 2, "cylinder": 3, "mesh": 4}[kind])
    size = [0.03, 0.02, 0.05]
    if kind == "mesh":
        trimesh.creation.box(extents=size).export(tmp_path / "block.stl")
    separated = penetrating = 0
    for _ in range(12):
        p, R = random_pose(rng)
        obstacles = []
        for k in range(4):
            o = {"id": f"o{k}", "position": near_cable_point(rng, ROBOT2, p, R, 0.03),
                 "quaternion": random_quaternion(rng)}
            if kind == "cylinder":
                o.update(type="cylinder", radius=0.012, height=0.05)
            elif kind == "box":
                o.update(type="box", size=size)
            else:
                o.update(type="mesh", file="block.stl")
            obstacles.append(o)
        cm = CollisionModel(ROBOT2, scene_from_dict({"cable_radius": R_CABLE,
                                                     "obstacles": obstacles}, base_dir=tmp_path))
        Bw = platform_anchors(ROBOT2, p, R)
        for (oid, i), d in cable_obstacle_distances(cm, p, R).items():
            o = obstacles[int(oid[1:])]
            c, Ro = np.array(o["position"]), Rotation.from_quat(o["quaternion"]).as_matrix()
            if kind == "cylinder":
                signed = (lambda x: cylinder_signed(x, c, Ro, 0.012, 0.05))
            else:
                signed = (lambda x: box_signed(x, c, Ro, size))
            ref, err = sampled_capsule(ROBOT2.base_anchors[i], Bw[i], signed, R_CABLE)
            # the sampled minimum is within err above the true one; in contact a box or
            # cylinder is the kernel's (its axis's deepest point less r: the same bounds),
            # a mesh coal's penetration depth (deeper)
            if ref > err or kind != "mesh":
                assert ref - err - 1e-8 <= d <= ref + 1e-8
            elif ref < -err:
                assert d <= ref + 1e-8
            separated += ref > err
            penetrating += ref < -err
    assert separated > 20 and penetrating > 0


def test_cable_pairs_match_the_least_squares_segment_distance():
    rng = np.random.default_rng(5)
    # a robot whose anchors are all distinct (no exemption) and Robot 2 (shared ones)
    A = ROBOT2.base_anchors + rng.uniform(-0.02, 0.02, (6, 3))
    B = ROBOT2.platform_anchors + rng.uniform(-0.02, 0.02, (6, 3))
    import dataclasses
    robot = dataclasses.replace(ROBOT2, base_anchors=A, platform_anchors=B)
    rho = 0.01
    for rb in (robot, ROBOT2):
        cm = model([], robot=rb, shared_anchor_exemption=rho)
        for _ in range(10):
            p, R = random_pose(rng)
            Bw = platform_anchors(rb, p, R)
            for kind, _, (i, j), d in cm.distances(p, R):
                ends = []
                for k in (i, j):
                    a, b = rb.base_anchors[k], Bw[k]
                    u = (b - a) / np.linalg.norm(b - a)
                    shared_b = np.allclose(rb.platform_anchors[i], rb.platform_anchors[j])
                    shared_a = np.allclose(rb.base_anchors[i], rb.base_anchors[j])
                    ends.append((a + rho * u * shared_a, b - rho * u * shared_b))
                exact = segment_segment(*ends[0], *ends[1]) - 2 * R_CABLE
                assert d == pytest.approx(exact, abs=1e-9)


@pytest.mark.parametrize("alpha_deg", [5.0, 11.0, 12.0, 40.0])
def test_cables_from_a_shared_anchor_touch_iff_r_over_sin_half_angle_exceeds_rho(alpha_deg):
    """Two cables of Robot 2 share a platform anchor; turn the platform so the two leave it
    at angle alpha: with r = 1 mm and rho = 10 mm they touch iff alpha < 11.48 degrees."""
    # a robot with one shared platform anchor and the two cables alpha apart
    import dataclasses
    alpha = math.radians(alpha_deg)
    L = 0.3
    A = ROBOT2.base_anchors.copy()
    B = ROBOT2.platform_anchors.copy()
    p, R = np.array([0.0, 0.0, 0.4]), np.eye(3)
    tip = p + B[0]
    for k, sign in ((0, -1), (1, 1)):
        A[k] = tip + L * np.array([math.sin(sign * alpha / 2), 0.0, -math.cos(alpha / 2)])
    robot = dataclasses.replace(ROBOT2, base_anchors=A)
    cm = model([], robot=robot, radius=0.001, shared_anchor_exemption=0.01)
    d = {c: dist for kind, _, c, dist in cm.distances(p, R)}[(0, 1)]
    assert (d < 0) == (0.001 / math.sin(alpha / 2) > 0.01)
    assert d == pytest.approx(2 * 0.01 * math.sin(alpha / 2) - 0.002, abs=1e-12)


def test_platform_box_against_spheres_matches_the_closed_form():
    rng = np.random.default_rng(6)
    size = [0.14, 0.14, 0.01]
    q_local = random_quaternion(rng)
    platform = {"type": "box", "size": size, "position": [0.0, 0.0, 0.01], "quaternion": q_local}
    for _ in range(20):
        p, R = random_pose(rng)
        spheres = [{"id": f"s{k}", "type": "sphere", "radius": 0.01,
                    "position": (p + rng.uniform(-0.1, 0.1, 3)).tolist()} for k in range(4)]
        cm = model(spheres, platform=platform)
        Rb = R @ Rotation.from_quat(q_local).as_matrix()
        cb = p + R @ np.array([0.0, 0.0, 0.01])
        for kind, oid, _, d in cm.distances(p, R):
            if kind != "platform-obstacle":
                continue
            s = spheres[int(oid[1:])]
            exact = box_signed(np.array([s["position"]]), cb, Rb, size)[0] - 0.01
            assert d == pytest.approx(exact, abs=1e-7)


def test_the_pruned_least_distance_is_the_least_of_all_pairs_and_names_it():
    rng = np.random.default_rng(7)
    for n in range(25):
        p, R = random_pose(rng)
        kinds = ["sphere", "box", "cylinder"]
        obstacles = []
        for k in range(10):
            o = {"id": f"o{k}", "type": kinds[k % 3], "quaternion": random_quaternion(rng),
                 "position": near_cable_point(rng, ROBOT2, p, R, 0.05)}
            o.update({"sphere": {"radius": 0.01}, "box": {"size": [0.02, 0.03, 0.01]},
                      "cylinder": {"radius": 0.005, "height": 0.04}}[o["type"]])
            obstacles.append(o)
        cm = model(obstacles, platform={"type": "cylinder", "radius": 0.09, "height": 0.01},
                   clearance=0.001)
        every = cm.distances(p, R)
        kind, oid, cables, least = min(every, key=lambda t: t[3])
        c = cm.clearance(p, R)
        assert c.distance == pytest.approx(least, abs=1e-12)
        assert c.margin == pytest.approx(least - 0.001, abs=1e-12)
        assert (c.kind, c.obstacle, c.cables) == (kind, oid, cables) or \
            sorted(t[3] for t in every)[1] - least < 1e-12  # a tie may name either


def test_cables_against_the_platforms_own_shape_match_the_closed_form():
    """A spherical platform body (closed form: the distance of its centre to the cable
    cut short by the exemption at its platform anchor, less both radii); a ball about the
    anchors' centre is clear, a body reaching past an anchor is hit by its cable there."""
    rng = np.random.default_rng(11)
    rho, r = 0.01, R_CABLE
    for body_r, hits in ((0.05, False), (0.12, True)):
        cm = model([], platform={"type": "sphere", "radius": body_r, "position": [0, 0, 0.02]},
                   shared_anchor_exemption=rho)
        for _ in range(10):
            p, R = random_pose(rng)
            centre = p + R @ np.array([0.0, 0.0, 0.02])
            Bw = platform_anchors(ROBOT2, p, R)
            got = {c[0]: d for kind, _, c, d in cm.distances(p, R) if kind == "cable-platform"}
            assert sorted(got) == list(range(6))
            for i, d in got.items():
                a, b = ROBOT2.base_anchors[i], Bw[i]
                cut = b + rho * (a - b) / np.linalg.norm(a - b)
                assert d == pytest.approx(point_segment(centre, a, cut) - body_r - r, abs=1e-7)
            c = cm.clearance(p, R)
            assert (c.kind == "cable-platform") == hits or c.distance > min(got.values())
            if hits:
                assert not c.ok and c.obstacle == "platform" and "/ platform" in c.binding


@pytest.mark.parametrize("kind", ["box", "cylinder", "mesh"])
def test_cables_against_a_box_cylinder_or_mesh_platform_match_sampled_distances(kind, tmp_path):
    """Box and cylinder platforms: the kernel's golden-section search on the convex signed
    distance (in contact: the deepest point of the cable's axis, less its radius); a mesh
    platform (a box written to STL): coal (in contact: its penetration depth, deeper).
    Against the signed distance sampled along each cable (cut short by the exemption),
    rotated shapes, contacts too."""
    trimesh = pytest.importorskip("trimesh")
    rng = np.random.default_rng({"box": 12, "cylinder": 13, "mesh": 14}[kind])
    size, rho, q_local = [0.2, 0.16, 0.03], 0.01, random_quaternion(rng)
    shape = {"box": {"type": "box", "size": size},
             "cylinder": {"type": "cylinder", "radius": 0.095, "height": 0.03},
             "mesh": {"type": "mesh", "file": "plate.stl"}}[kind]
    trimesh.creation.box(extents=size).export(tmp_path / "plate.stl")
    platform = dict(shape, position=[0.0, 0.0, 0.01], quaternion=q_local)
    scene = scene_from_dict({"cable_radius": R_CABLE, "obstacles": [], "platform": platform},
                            base_dir=tmp_path)
    cm = CollisionModel(ROBOT2, scene)
    hits = 0
    for _ in range(10):
        p, R = random_pose(rng)
        Rb, centre = R @ Rotation.from_quat(q_local).as_matrix(), p + R @ np.array([0, 0, 0.01])
        signed = (lambda x: cylinder_signed(x, centre, Rb, 0.095, 0.03)) if kind == "cylinder" \
            else (lambda x: box_signed(x, centre, Rb, size))
        Bw = platform_anchors(ROBOT2, p, R)
        got = {c[0]: d for k, _, c, d in cm.distances(p, R) if k == "cable-platform"}
        assert sorted(got) == list(range(6))
        for i, d in got.items():
            a, b = ROBOT2.base_anchors[i], Bw[i]
            cut = b + rho * (a - b) / np.linalg.norm(a - b)
            sampled, err = sampled_capsule(a, cut, signed, R_CABLE)
            if kind != "mesh" or sampled > err:
                assert sampled - err - 1e-7 <= d <= sampled + 1e-7
            else:   # coal's penetration depth (EPA): at least the deepest axis point's
                assert d <= sampled + 1e-7 and d < 0
            hits += d < 0
        c = cm.clearance(p, R)
        assert c.distance == pytest.approx(min(t[3] for t in cm.distances(p, R)), abs=1e-12)
    assert hits > 0   # anchors inside the body's outline: some cables pass through it


def lower_bounds(cm, p, R):
    """The kernel's lower bounds (m + 1, K + 1), m, of the cable-obstacle (rows 0..m-1,
    columns 0..K-1), platform-obstacle (row m) and cable-platform (column K) distances at
    pose (p, R), from bounding spheres (inf: not checked): the model's buffers after the
    kernel's pass over one pose, before coal consumes them."""
    cm._pose(p, R)
    return cm.lb.copy()


def test_lower_bounds_never_exceed_the_exact_distance():
    """The platform's bounds against box obstacles; the cables' against primitive
    obstacles are consumed by the kernel (exact there: inf, nothing left for coal)."""
    rng = np.random.default_rng(8)
    for _ in range(10):
        p, R = random_pose(rng)
        obstacles = [{"id": f"b{k}", "type": "box", "size": [0.04, 0.01, 0.02],
                      "quaternion": random_quaternion(rng),
                      "position": near_cable_point(rng, ROBOT2, p, R, 0.05)} for k in range(6)]
        cm = model(obstacles, platform={"type": "box", "size": [0.14, 0.14, 0.01]})
        lb = lower_bounds(cm, p, R)
        assert lb.shape == (7, 7) and lb[6, 6] == math.inf
        for kind, oid, cables, d in cm.distances(p, R):
            row = cables[0] if kind in ("cable-obstacle", "cable-platform") else 6
            if kind == "platform-obstacle":   # a box platform's cables: exact, no bound
                assert lb[row, int(oid[1:])] <= d + 1e-12
        assert np.all(lb[:6, :6] == math.inf)
        assert np.all(lb[:, 6] == math.inf)


def test_an_empty_scene_binds_only_cable_pairs_and_robot2_cables_clear_each_other():
    cm = model([], radius=0.001)
    c = cm.clearance(np.array([0.0, 0.0, 0.4]), np.eye(3))
    # closest base anchors are 4.25 mm apart: 2.25 mm between 1 mm cables near the base
    assert c.kind == "cable-cable" and c.ok and 0.0 < c.distance < 0.00425 - 0.002 + 1e-9
    assert c.binding.count("winch_") == 2
