"""frames.py: quaternion algebra against scipy, the transform book's chains, refusals and
bound, and the z-up <-> paper frame turn being exact."""

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from cdh_planner.errors import InputError
from cdh_planner.ros.core.frames import (IDENTITY, Z_DOWN, TransformBook, compose, inverse,
                                    pose_in_frame, quat_multiply, quat_rotate, transform_msg)
from cdh_planner.ros.msgs.messages import pose_stamped_msg

RNG = np.random.default_rng(23)


def _random():
    return Rotation.random(random_state=RNG).as_quat(), RNG.normal(size=3)


def test_quaternion_product_and_rotation_are_scipys():
    for _ in range(20):
        (a, _), (b, v) = _random(), _random()
        ab = Rotation.from_quat(a) * Rotation.from_quat(b)
        np.testing.assert_allclose(Rotation.from_quat(quat_multiply(a, b)).as_matrix(),
                                   ab.as_matrix(), atol=1e-14)
        np.testing.assert_allclose(quat_rotate(a, v), Rotation.from_quat(a).apply(v), atol=1e-14)


def test_inverse_and_compose():
    for _ in range(20):
        a = _random()
        q, t = compose(a, inverse(a))
        np.testing.assert_allclose(Rotation.from_quat(q).as_matrix(), np.eye(3), atol=1e-14)
        np.testing.assert_allclose(t, 0.0, atol=1e-14)


def _book(*edges):
    book = TransformBook()
    for parent, child, transform in edges:
        book.add(transform_msg(parent, child, transform, None))
    return book


def test_lookup_through_a_tree_maps_points_as_the_chain_does():
    a, b, c = _random(), _random(), _random()
    book = _book(("world", "base", a), ("base", "tool", b), ("world", "table", c))
    x = RNG.normal(size=3)
    q, t = book.lookup("table", "tool")             # tool -> world -> table
    in_world = quat_rotate(a[0], quat_rotate(b[0], x) + b[1]) + a[1]
    expected = quat_rotate(inverse(c)[0], in_world) + inverse(c)[1]
    np.testing.assert_allclose(quat_rotate(q, x) + t, expected, atol=1e-13)
    assert book.lookup("base", "base") is IDENTITY


def test_unconnected_frames_are_refused_naming_them():
    book = _book(("world", "base", Z_DOWN), ("map", "odom", IDENTITY))
    with pytest.raises(LookupError, match="no transform from 'odom' to 'base'.*map, odom"):
        book.lookup("base", "odom")
    msg = pose_stamped_msg([0, 0, 0.3], np.eye(3), "nowhere")
    with pytest.raises(InputError, match="goal.header.frame_id = 'nowhere': no transform"):
        pose_in_frame(book, msg, "base", "goal")


def test_the_z_up_turn_is_exact_both_ways():
    book = _book(("world", "cdh_base", Z_DOWN))
    for _ in range(20):
        q, p = _random()
        msg = pose_stamped_msg(p, Rotation.from_quat(q).as_matrix(), "cdh_base")
        there = pose_in_frame(book, msg, "world", "goal")
        back = pose_in_frame(book, there, "cdh_base", "goal")
        assert back.pose == msg.pose                   # bit for bit
        assert there.pose.position.z == -msg.pose.position.z


def test_a_loop_in_tf_does_not_hang_and_the_book_is_bounded():
    book = _book(("a", "b", IDENTITY), ("b", "a", IDENTITY))
    with pytest.raises(LookupError):
        book.lookup("a", "c")
    small = TransformBook(max_frames=2)
    assert small.add(transform_msg("w", "x", IDENTITY, None))
    assert small.add(transform_msg("w", "y", IDENTITY, None))
    assert not small.add(transform_msg("w", "z", IDENTITY, None))
    assert small.add(transform_msg("w", "x", Z_DOWN, None))      # an update still fits


def test_tf_message_has_the_real_tf2_msgs_type_hash():
    """/tf must carry the standard type: the venv's partial copy (interfaces/tf2_msgs) hashes
    as ROS 2 Jazzy's tf2_msgs/msg/TFMessage (`ros2 topic info -v /tf` on Jazzy)."""
    import json
    from pathlib import Path
    from ament_index_python.packages import get_package_share_directory
    description = Path(get_package_share_directory("tf2_msgs")) / "msg" / "TFMessage.json"
    hashes = {h["type_name"]: h["hash_string"]
              for h in json.loads(description.read_text())["type_hashes"]}
    assert hashes["tf2_msgs/msg/TFMessage"] == \
        "RIHS01_e369d0f05a23ae52508854b66f6aa0437f3449d652e8cbf22d5abe85d020f087"
