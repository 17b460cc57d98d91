"""Collision joined to wrench feasibility as one margin (numpy only, so that importing the
planner does not load the collision library or compile its kernel: ``collision.py`` does,
once a scene is given)."""

import numpy as np

COLLISION_UNIT_M = 0.1  # m of clearance that count as a normalised margin of 1


def combine(margin, binding, collision, p, R):
    """The margins (N,) and bindings (N,) of wrench feasibility (normalised, from
    ``wrench``) and of collision (``collision``: a CollisionModel or None)
    at poses (p, R): the least of the two, the collision margin in units of
    COLLISION_UNIT_M; positive iff the pose is wrench-feasible and collision-free."""
    if collision is None:
        return margin, binding
    cm, cb = collision.margins(p, R)
    cm = cm / COLLISION_UNIT_M
    worse = cm < margin
    return np.where(worse, cm, margin), np.where(worse, cb, binding)
