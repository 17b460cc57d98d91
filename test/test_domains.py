"""The demo's ROS domain: ROS_DOMAIN_ID when set (so that it can be watched live), a claimed
one otherwise; a bad ROS_DOMAIN_ID is refused naming it."""

import pytest

from cdh_planner.errors import InputError
from cdh_planner.ros.isolation import DOMAINS, MAX_DOMAIN_ID, chosen_domain, claimed_domain


def test_ros_domain_id_is_used_when_set():
    with chosen_domain({"ROS_DOMAIN_ID": "142"}) as d:
        assert d == 142
    with chosen_domain({"ROS_DOMAIN_ID": "0"}) as d:
        assert d == 0


def test_a_held_ros_domain_id_is_still_the_one_asked_for():
    with claimed_domain() as held, chosen_domain({"ROS_DOMAIN_ID": str(held)}) as d:
        assert d == held


def test_without_ros_domain_id_a_domain_of_its_own():
    for env in ({}, {"ROS_DOMAIN_ID": ""}, {"ROS_DOMAIN_ID": "  "}):
        with chosen_domain(env) as d:
            assert d in DOMAINS


@pytest.mark.parametrize("text", ["abc", "-1", "1.5", str(MAX_DOMAIN_ID + 1)])
def test_a_bad_ros_domain_id_is_refused_naming_it(text):
    with pytest.raises(InputError, match=f"ROS_DOMAIN_ID = '{text}'"):
        with chosen_domain({"ROS_DOMAIN_ID": text}):
            pass


def test_a_released_domain_comes_back_only_after_the_others():
    """A node killed in a domain lingers in the graph until its lease ends: the next claims
    take the domains released longest ago, so 20 claims in a row are 20 different ids."""
    from cdh_planner.ros.isolation import claimed_domain
    seen = []
    for _ in range(20):
        with claimed_domain() as d:
            seen.append(d)
    assert len(set(seen)) == 20, seen
