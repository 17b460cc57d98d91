"""The start-up ports, in one place: numpy ports of scipy's rotations and C2 splines
(rotation.py, splines.py) and toppra imported without matplotlib and scipy's
interpolate and sparse (lean_toppra.py). They save about 0.4 s of a short plan's
0.55 s and give scipy's answers to rounding (test_rotation_splines.py).

    from ..ports import Rotation, Slerp, CubicSpline, RotationSpline, solve_banded
    toppra = ports.import_toppra()

The one switch back: ``CDH_PLANNER_USE_SCIPY=1`` in the environment (read at import)
makes these names scipy's own classes and ``import_toppra`` toppra's own import
(test_ports.py plans with both and compares).
"""

import os

USE_SCIPY = os.environ.get("CDH_PLANNER_USE_SCIPY", "") not in ("", "0")

if USE_SCIPY:
    from scipy.interpolate import CubicSpline
    from scipy.linalg import solve_banded
    from scipy.spatial.transform import Rotation, RotationSpline, Slerp
else:
    from .rotation import Rotation, Slerp
    from .splines import CubicSpline, RotationSpline, solve_banded


def spline_derivatives(spline, xs):
    """[value, first, second derivative] at xs (M,) of a CubicSpline or (rotation, rate,
    acceleration) of a RotationSpline: the ports' ``derivatives`` (the pieces found once),
    scipy's one call per order."""
    if USE_SCIPY:
        return spline(xs), spline(xs, 1), spline(xs, 2)
    return spline.derivatives(xs)


def import_toppra():
    """The toppra package, its ``algorithm`` and ``constraint`` modules imported."""
    if USE_SCIPY:
        import toppra.algorithm
        import toppra.constraint
        return toppra
    from .lean_toppra import import_lean
    return import_lean()


__all__ = ["CubicSpline", "Rotation", "RotationSpline", "Slerp", "USE_SCIPY", "import_toppra",
           "solve_banded", "spline_derivatives"]
