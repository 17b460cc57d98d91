"""Collision joined to wrench feasibility as one margin (numpy only, so that importing the
planner does not load the collision library or compile its kernel: ``collision.py`` does,
once a scene is given)."""

import numpy as np

COLLISION_UNIT_M = 0.1  # m of clearance that count as a normalised margin of 1


def combine(margin, binding, collision, p, R, motion=False):
    """The margins (N,) and bindings (N,) of wrench feasibility (normalised, from
    ``wrench``) and of collision (``collision``: a CollisionModel or None)
    at poses (p, R): the least of the two, the collision margin in units of
    COLLISION_UNIT_M; positive iff the pose is wrench-feasible and collision-free.
    ``motion``: the poses are consecutive poses of a motion (close to one another), whose
    collision margins are then computed only where they might be the lesser
    (``CollisionModel.margins_along``, the same result)."""
    if collision is None:
        return margin, binding
    if motion:  # elsewhere a bound above the wrench margin: the wrench margin stays
        cm, cb = collision.margins_along(p, R, np.asarray(margin) * COLLISION_UNIT_M)
    else:
        cm, cb = collision.margins(p, R)
    cm = cm / COLLISION_UNIT_M
    worse = cm < margin
    return np.where(worse, cm, margin), np.where(worse, cb, binding)
