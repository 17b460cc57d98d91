"""The collision kernel over batches of poses: ``CollisionModel.margins`` (one compiled
call for the batch, coal only near obstacles) equals ``clearance`` pose by pose, and
``margins_only`` its margins bit for bit; the
ahead-of-time kernel (scene/aot.py) is the JIT kernel's twin and a fresh process with it
compiles nothing (numba is never imported; its naming: test_kernel_aot.py)."""

import subprocess
import sys

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from cdh_planner.scene import kernels
from cdh_planner.scene.collision import CollisionModel
from cdh_planner.scene.schema import scene_from_dict

from conftest import CONFIG, aot_built
from test_scene_distances import ROBOT2, model, near_cable_point, random_quaternion

AOT_BUILT = aot_built(kernels)
PLATFORMS = [None, {"type": "box", "size": [0.14, 0.14, 0.01]},
             {"type": "cylinder", "radius": 0.09, "height": 0.01},
             {"type": "sphere", "radius": 0.05, "position": [0.0, 0.0, 0.02]},
             {"type": "capsule", "radius": 0.03, "length": 0.1, "quaternion": [0.6, 0, 0, 0.8]}]


def poses(rng, n, spread=0.06):
    p = np.array([0.0, 0.0, 0.40]) + rng.uniform(-spread, spread, (n, 3))
    R = Rotation.from_rotvec(rng.uniform(-0.3, 0.3, (n, 3))).as_matrix()
    return p, R


def crowded_model(rng, platform, clearance=0.0001):
    """Three obstacles, one of each primitive type, near the cables of a random pose: a
    batch holds poses that hit and poses that miss them."""
    p, R = poses(rng, 1)
    kinds = ["sphere", "box", "cylinder"]
    obstacles = []
    for k in range(3):
        o = {"id": f"o{k}", "type": kinds[k % 3], "quaternion": random_quaternion(rng),
             "position": near_cable_point(rng, ROBOT2, p[0], R[0], 0.05)}
        o.update({"sphere": {"radius": 0.01}, "box": {"size": [0.02, 0.03, 0.01]},
                  "cylinder": {"radius": 0.005, "height": 0.04}}[o["type"]])
        obstacles.append(o)
    return model(obstacles, platform=platform, clearance=clearance)


@pytest.mark.parametrize("platform", PLATFORMS, ids=["none", "box", "cylinder", "sphere", "capsule"])
def test_batch_margins_equal_the_clearance_of_each_pose(platform):
    rng = np.random.default_rng(11)
    hit = 0
    for _ in range(4):
        cm = crowded_model(rng, platform)
        p, R = poses(rng, 60)
        margin, binding = cm.margins(p, R)
        assert np.array_equal(cm.margins_only(p, R), margin)  # the same numbers, unnamed
        for n in range(len(p)):
            c = cm.clearance(p[n], R[n])
            assert margin[n] == pytest.approx(c.margin, abs=1e-12)
            assert binding[n] == f"collision {c.binding}"
            hit += c.margin < 0
    assert 20 < hit < 220  # both kinds of pose


def test_batch_of_one_pose_and_of_none():
    cm = crowded_model(np.random.default_rng(5), None)
    p, R = poses(np.random.default_rng(6), 1)
    assert cm.margins(p[0], R[0])[0][0] == pytest.approx(cm.clearance(p[0], R[0]).margin, abs=1e-12)
    margin, binding = cm.margins(np.empty((0, 3)), np.empty((0, 3, 3)))
    assert margin.shape == binding.shape == cm.margins_only(np.empty((0, 3)), np.empty((0, 3, 3))).shape == (0,)


def test_an_empty_scene_batch_names_cable_pairs():
    cm = CollisionModel(ROBOT2, scene_from_dict({"cable_radius": 0.001, "obstacles": []}))
    p, R = poses(np.random.default_rng(2), 20)
    margin, binding = cm.margins(p, R)
    for n in range(len(p)):
        c = cm.clearance(p[n], R[n])
        assert c.kind == "cable-cable" and margin[n] == pytest.approx(c.margin, abs=1e-12)
        assert binding[n] == f"collision {c.binding}"


@pytest.mark.skipif(not AOT_BUILT, reason="no ahead-of-time collision kernel built (make, or "
                                          "python -m cdh_planner.scene.aot)")
@pytest.mark.parametrize("platform", PLATFORMS, ids=["none", "box", "cylinder", "sphere", "capsule"])
def test_aot_and_jit_kernels_agree_bit_for_bit(platform):
    rng = np.random.default_rng(8)
    cm = crowded_model(rng, platform)
    p, R = poses(rng, 40)
    out = {}
    for name, kernel in (("aot", kernels.aot_kernel()), ("jit", kernels.jit_kernel())):
        buffers = cm._buffers(len(p))
        for b in buffers:  # what the kernel leaves unwritten (frames_p of a primitive platform)
            b.fill(0.0)
        kernel(p, R, cm.static, cm.pairs, *buffers)
        out[name] = buffers
    for a, j in zip(out["aot"], out["jit"]):
        np.testing.assert_array_equal(a, j)


@pytest.mark.skipif(not AOT_BUILT, reason="no ahead-of-time collision kernel built (make, or "
                                          "python -m cdh_planner.scene.aot)")
def test_aot_and_jit_cable_obstacle_distances_agree_bit_for_bit():
    """The unpruned cable-obstacle entry (``CollisionModel.cable_obstacle_distances``) on
    a sphere, a box and a cylinder near the cables: hits and misses."""
    rng = np.random.default_rng(9)
    cm = crowded_model(rng, None)
    p, R = poses(rng, 40)
    aot_entry = kernels.aot.load(kernels)["cable_obstacle_batch"]
    jit_entry = kernels.jit_kernels()["cable_obstacle_batch"]
    out = [np.zeros((len(p), cm.m, cm.K)) for _ in range(2)]
    for entry, o in zip((aot_entry, jit_entry), out):
        entry(p, R, cm.static, cm.pairs, o)
    np.testing.assert_array_equal(out[0], out[1])
    assert np.isfinite(out[0]).all() and (out[0] < 0).any() and (out[0] > 0).any()


@pytest.mark.skipif(not AOT_BUILT, reason="no ahead-of-time collision kernel built")
def test_with_the_aot_kernel_a_fresh_process_compiles_nothing():
    """A scene loaded and a pose checked in a fresh process: numba is never imported, so
    nothing is compiled (the JIT's first call costs about a second)."""
    code = ("import sys\nimport numpy as np\n"
            "from cdh_planner.model.robot import load_robot\n"
            "from cdh_planner.scene.collision import CollisionModel\n"
            "from cdh_planner.scene.schema import load_scene\n"
            f"robot = load_robot({str(CONFIG / 'robot2.yaml')!r})\n"
            f"scene = load_scene({str(CONFIG / 'scenes' / 'robot2_ball.yaml')!r}, robot)\n"
            "c = CollisionModel(robot, scene).clearance(np.array([0, 0, 0.4]), np.eye(3))\n"
            "assert c.distance > 0\n"
            "print('numba' in sys.modules)")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True)
    assert out.stdout.strip() == "False"


def test_coal_is_imported_only_when_a_pair_needs_it():
    """Primitive obstacles and no platform shape: clearance, batches and every pair's
    distances come from the compiled kernel and coal is never imported; a box platform's
    pairs against an obstacle are coal's, so the first distances() imports it."""
    code = ("import sys\nimport numpy as np\n"
            "from cdh_planner.model.robot import load_robot\n"
            "from cdh_planner.scene.collision import CollisionModel\n"
            "from cdh_planner.scene.schema import scene_from_dict\n"
            f"robot = load_robot({str(CONFIG / 'robot2.yaml')!r})\n"
            "obstacles = [{'id': 'ball', 'type': 'sphere', 'radius': 0.01, 'position': [0, 0.05, 0.2]},\n"
            "             {'id': 'block', 'type': 'box', 'size': [0.02, 0.03, 0.01], 'position': [0.05, 0, 0.2]}]\n"
            "cm = CollisionModel(robot, scene_from_dict({'obstacles': obstacles}))\n"
            "p, R = np.array([[0, 0, 0.4]] * 3), np.tile(np.eye(3), (3, 1, 1))\n"
            "cm.clearance(p[0], R[0]), cm.margins(p, R), cm.distances(p[0], R[0])\n"
            "before = 'coal' in sys.modules\n"
            "box = {'type': 'box', 'size': [0.14, 0.14, 0.01]}\n"
            "cm = CollisionModel(robot, scene_from_dict({'obstacles': obstacles, 'platform': box}))\n"
            "cm.distances(p[0], R[0])\n"
            "print(before, 'coal' in sys.modules)")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True)
    assert out.stdout.strip() == "False True"
