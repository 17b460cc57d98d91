"""Platform poses from files and command-line values, validated field by field.

A poses file is JSON: a list of poses, or ``{"poses": [...]}``. Each pose is

    {"position": [x, y, z], "quaternion": [x, y, z, w]}     (m; ROS order, unit norm)
    {"position": [x, y, z], "tau": [phi, theta, sigma]}     (m; rad, theta in [0, pi])

Positions lie within +-1e3 m (``errors.MAX_POSITION_M``); a file holds at most MAX_POSES
poses. Every error is an InputError naming the entry, e.g. ``poses[3].quaternion``. Nothing is
silently fixed: a non-normalised quaternion or an out-of-range tilt is usually a unit or
ordering mistake (degrees, w first) and is reported, not normalised away.

Command-line quantities: ``parse_angle`` accepts radians (``0.75``, ``-pi``, ``pi/2``,
``3pi/4``, ``0.5*pi``) or degrees (``34deg``), ``parse_length`` metres (``0.35``, ``350mm``);
both within +-1e3.
"""

import gc
import itertools
import re
from contextlib import contextmanager
from dataclasses import dataclass

import numpy as np
import orjson

from .. import compiled_json
from ..errors import MAX_POSITION_M, InputError, check_keys, check_numbers
from ..files import JSON_LIMITS, decode_text, parse_json_text, read_bytes
from ..model.pose import check_quaternion, quaternion_from_tau, rotation_from_quaternion, \
    tau_from_quaternion

POSE_KEYS = ("position", "quaternion", "tau")
# |phi|, |sigma| beyond this (rad) are almost surely degrees; theta must be in [0, pi].
ANGLE_LIMIT = 2.0 * np.pi + 1e-9
THETA_TOL = 1e-9
MAX_POSES = 100_000


@dataclass(frozen=True)
class PoseList:
    """N validated poses. ``positions`` (N, 3) m, ``quaternions`` (N, 4) (x, y, z, w) with
    w >= 0, ``rotations`` (N, 3, 3), ``tau`` (N, 3) rad (as given, or from the quaternion)."""

    positions: np.ndarray
    quaternions: np.ndarray
    rotations: np.ndarray
    tau: np.ndarray

    def __len__(self):
        return self.positions.shape[0]


def load_poses(path, where="poses"):
    """Read and validate a poses JSON file; InputError on any bad content (the file's size,
    depth and list lengths bounded by ``files.JSON_LIMITS``, at most MAX_POSES poses)."""
    data = read_bytes(path, where, JSON_LIMITS.max_bytes)
    bulk = _compiled_poses(data)
    if bulk is not None:
        return bulk
    text = decode_text(data, path, where)
    with _no_collection():
        bulk = _bulk_text(text)
    if bulk is not None:
        return bulk
    return poses_from_obj(parse_json_text(text, where, str(path)), where)


def _compiled_poses(data):
    """The PoseList of a poses file's bytes ``data`` in its plain form (ASCII JSON, so no
    text to decode), read straight into arrays by compiled C (``compiled_json.read_poses``:
    0.010 s for 20,000 poses, orjson and the lists 0.025 s), or None for any other form, a
    value ``_bulk_poses`` would refuse, or without the build: then orjson and the json
    module (``_bulk_text``). The same numbers (both read as correctly rounded doubles) and
    checks (the C reads finite numbers only; ``_within`` the limits)."""
    read = compiled_json.read_poses(data, MAX_POSES)
    if read is None:
        return None
    values, has_q = read
    p = np.ascontiguousarray(values[:, :3])
    q, tau = values[has_q, 3:7], values[~has_q, 3:6]  # copies, C-contiguous
    if not (_within(p, MAX_POSITION_M) and _within(q, QUATERNION_LIMIT)):
        return None
    return _pose_list(p, has_q, q, tau)


@contextmanager
def _no_collection():
    """Python's cyclic garbage collector off within: a parsed poses document is a tree of
    some 60,000 lists and dicts for 20,000 poses (no cycles to find), whose allocation
    would otherwise trigger collections that scan it again and again (14 of the 55 ms of
    reading such a file). Left as it was (a caller may have turned it off)."""
    enabled = gc.isenabled()
    gc.disable()
    try:
        yield
    finally:
        if enabled:
            gc.enable()


def _bulk_text(text):
    """The PoseList of a poses file's ``text`` parsed by orjson (35 ms for 20,000 poses,
    the json module with its duplicate-key hook 57 ms) if ``_bulk_poses`` accepts it and no
    key is given twice, else None: the json module's parse and the pose-by-pose check then
    say what is wrong. orjson keeps the last of a repeated key silently, so the quotes are
    counted: every string of a document ``_bulk_poses`` accepts is a key (the values are
    numbers), and its text has 2 quotes a key iff no key is given twice. Such a document
    is within JSON_LIMITS (see _Q_KEYS): no ``check_structure`` walk."""
    try:
        doc = orjson.loads(text)
    except orjson.JSONDecodeError:  # NaN, over 64-bit integers, bad JSON: the json module's say
        return None
    wrapped = isinstance(doc, dict) and doc.keys() == {"poses"}
    rows = doc["poses"] if wrapped else doc
    if not (isinstance(rows, list) and 0 < len(rows) <= MAX_POSES):
        return None
    if text.count('"') != 2 * (2 * len(rows) + wrapped):
        return None
    return _bulk_poses(rows)


def poses_from_obj(doc, where="poses"):
    """Validate a decoded poses document (a list, or a mapping with only ``poses``)."""
    if isinstance(doc, dict):
        doc = check_keys("", doc, ("poses",), required=("poses",))["poses"]
    if not isinstance(doc, list):
        raise InputError(where, doc, "expected a list of poses")
    if not doc:
        raise InputError(where, doc, "empty pose list: give at least one pose")
    if len(doc) > MAX_POSES:
        raise InputError(where, f"{len(doc)} poses", f"at most {MAX_POSES} poses")
    bulk = _bulk_poses(doc)
    if bulk is not None:
        return bulk
    fields = [_pose_fields(d, f"{where}[{i}]") for i, d in enumerate(doc)]
    p = np.array([f[0] for f in fields], dtype=float)
    has_q = np.array([f[1] == "quaternion" for f in fields])
    values = np.array([f[2] for f in fields if f[1] == "quaternion"], dtype=float).reshape(-1, 4)
    q = np.empty((len(doc), 4))
    tau = np.empty((len(doc), 3))
    if has_q.any():
        q[has_q] = values
        tau[has_q] = tau_from_quaternion(values)
    if not has_q.all():
        tau[~has_q] = np.array([f[2] for f in fields if f[1] == "tau"], dtype=float)
        q[~has_q] = quaternion_from_tau(tau[~has_q])
    return PoseList(positions=p, quaternions=q, rotations=rotation_from_quaternion(q), tau=tau)


def _bulk_poses(doc):
    """The PoseList of ``doc`` (a list of poses) checked as whole arrays, or None if any pose
    might be bad: then the pose-by-pose check (``_pose_fields``) names the first bad field.
    Every test here is one that ``_pose_fields`` makes, so both accept the same files."""
    if set(map(type, doc)) != {dict}:
        return None
    kinds = set(map(frozenset, doc))
    if not kinds <= {_Q_KEYS, _TAU_KEYS}:
        return None
    p = _bulk_numbers([d["position"] for d in doc], 3, MAX_POSITION_M)
    if p is None:
        return None
    has_q = np.fromiter(("quaternion" in d for d in doc), bool, len(doc))
    q = tau = None
    if has_q.any():
        q = _bulk_numbers([d["quaternion"] for d in doc if "quaternion" in d], 4,
                          QUATERNION_LIMIT)
    if not has_q.all():
        tau = _bulk_numbers([d["tau"] for d in doc if "tau" in d], 3, None)
    if (q is None and has_q.any()) or (tau is None and not has_q.all()):
        return None
    return _pose_list(p, has_q, q, tau)


def _pose_list(p, has_q, q_values, tau_values):
    """The PoseList of positions p (N, 3) m and, where ``has_q`` (N,), the quaternions
    ``q_values`` (as given: normalised here), elsewhere the ``tau_values`` (rad), or None if
    a quaternion is not of unit norm or a tau out of range (``_pose_fields`` then names it)."""
    q, tau = np.empty((len(p), 4)), np.empty((len(p), 3))
    if has_q.any():
        values = q_values
        norm = np.sqrt(np.vecdot(values, values))  # np.linalg.norm's rounding, row by row
        if not np.all(np.abs(norm - 1.0) <= QUATERNION_TOL):
            return None
        values = values / norm[:, None]
        values[values[:, 3] < 0] *= -1.0
        q[has_q], tau[has_q] = values, tau_from_quaternion(values)
    if not has_q.all():
        values = tau_values
        if not _tau_in_range(values):
            return None
        values[:, 1] = np.clip(values[:, 1], 0.0, np.pi)
        tau[~has_q], q[~has_q] = values, quaternion_from_tau(values)
    return PoseList(positions=p, quaternions=q, rotations=rotation_from_quaternion(q), tau=tau)


_Q_KEYS, _TAU_KEYS = frozenset(("position", "quaternion")), frozenset(("position", "tau"))
# A pose document that _bulk_poses accepts is within JSON_LIMITS (test_verify_bulk): at most
# MAX_POSES poses of 10 values (a mapping, two lists, 7 numbers), 4 levels deep with the
# {"poses": ...} wrapper; load_poses skips the check_structure walk for it.
QUATERNION_TOL = 1e-3  # check_quaternion's default tolerance on |q| - 1
QUATERNION_LIMIT = 2.0  # |entry| of a given quaternion beyond this: refused before its norm


def _bulk_numbers(rows, n, limit):
    """``rows`` (lists of ``n`` ints or floats, not booleans) as an (len, n) float array if
    all are finite and within +-``limit`` (when given), else None."""
    if set(map(type, rows)) != {list} or set(map(len, rows)) != {n}:
        return None
    flat = list(itertools.chain.from_iterable(rows))
    if not set(map(type, flat)) <= {int, float}:
        return None
    try:
        values = np.array(flat, dtype=float).reshape(-1, n)
    except OverflowError:  # an integer beyond the float range
        return None
    if not (np.all(np.isfinite(values)) and _within(values, limit)):
        return None
    return values


def _within(values, limit):
    """Whether every entry of ``values`` lies within +-``limit`` (None: no limit)."""
    return limit is None or not np.any(np.abs(values) > limit)


def _tau_in_range(tau):
    """Whether every row of ``tau`` (N, 3) rad passes ``check_tau``."""
    return bool(np.all((tau[:, 1] >= -THETA_TOL) & (tau[:, 1] <= np.pi + THETA_TOL))
                and np.all(np.abs(tau[:, [0, 2]]) <= ANGLE_LIMIT))


def pose_from_dict(d, where):
    """One pose: (position (3,) m, quaternion (4,) with w >= 0, tau (3,) rad)."""
    p, kind, value = _pose_fields(d, where)
    if kind == "quaternion":
        return np.asarray(p), value, tau_from_quaternion(value)
    return np.asarray(p), quaternion_from_tau(value), value


def _pose_fields(d, where):
    """(position (3,), "quaternion" or "tau", the checked quaternion (w >= 0) or tau)."""
    if not isinstance(d, dict):
        raise InputError(where, d, "expected a mapping with 'position' and 'quaternion' or 'tau'")
    check_keys(where, d, POSE_KEYS, required=("position",))
    has_q, has_tau = "quaternion" in d, "tau" in d
    if has_q == has_tau:
        raise InputError(where, d, "give exactly one of 'quaternion' or 'tau'")
    p = number_list(f"{where}.position", d["position"], 3, limit=MAX_POSITION_M)
    if has_q:
        q = check_quaternion(number_list(f"{where}.quaternion", d["quaternion"], 4,
                                         limit=QUATERNION_LIMIT),
                             field=f"{where}.quaternion")
        return p, "quaternion", -q if q[3] < 0 else q
    return p, "tau", check_tau(number_list(f"{where}.tau", d["tau"], 3), f"{where}.tau")


def pose_values(values, where):
    """The 7 numbers ``x y z qx qy qz qw`` of a pose given on a command line
    (``cdh-planner call --start "..."``: a string, spaces or commas between the numbers, or
    7 numbers), as floats, checked as a pose file's pose is (``pose_from_values``)."""
    if isinstance(values, str):
        parts = values.replace(",", " ").split()
        try:
            values = [float(v) for v in parts]
        except ValueError:
            raise InputError(where, " ".join(parts), "expected 7 numbers: x y z qx qy qz qw "
                                                     "(m, quaternion)") from None
    values = list(values)
    pose_from_values(values, where)
    return [float(v) for v in values]


def pose_from_values(values, where):
    """A pose given as 7 numbers ``x y z qx qy qz qw`` (``cdh-planner call --start``):
    (position (3,) m, quaternion (4,) x y z w with w >= 0), checked as a pose file's pose
    (finite, positions within +-MAX_POSITION_M, a unit quaternion); InputError naming
    ``where.position[i]`` or ``where.quaternion``."""
    values = list(values)
    if len(values) != 7:
        raise InputError(where, values, "expected 7 numbers: x y z qx qy qz qw (m, quaternion)")
    p, q, _ = pose_from_dict({"position": values[:3], "quaternion": values[3:]}, where)
    return p, q


def number_list(where, value, n, limit=None):
    """A list of exactly ``n`` finite numbers (JSON NaN/Infinity, booleans and strings
    rejected), each within +-``limit`` when given."""
    return np.asarray(check_numbers(where, value, n, limit), dtype=float)


def check_tau(tau, where):
    """Tilt-and-torsion angles in rad: theta in [0, pi], |phi|, |sigma| <= 2 pi."""
    phi, theta, sigma = tau
    if not -THETA_TOL <= theta <= np.pi + THETA_TOL:
        raise InputError(f"{where}[1]", float(theta), "tilt theta must be in [0, pi] rad (degrees given?)")
    for i, a in ((0, phi), (2, sigma)):
        if abs(a) > ANGLE_LIMIT:
            raise InputError(f"{where}[{i}]", float(a), "must be within [-2 pi, 2 pi] rad (degrees given?)")
    return np.array([phi, np.clip(theta, 0.0, np.pi), sigma])


_UNSIGNED = r"(?:\d+\.?\d*|\.\d+)(?:[eE][+-]?\d+)?"
_NUMBER = r"[+-]?" + _UNSIGNED
_PI_FORM = re.compile(rf"^(?P<sign>[+-]?)(?P<k>{_UNSIGNED})?\s*\*?\s*pi(?:\s*/\s*(?P<d>{_UNSIGNED}))?$")


def parse_angle(text, where="angle"):
    """An angle in rad from ``0.75``, ``-pi``, ``pi/2``, ``3pi/4``, ``0.5*pi`` or ``34deg``."""
    s = str(text).strip().lower()
    try:
        if s.endswith("deg"):
            value = np.deg2rad(_plain_number(s[:-3].strip()))
        else:
            m = _PI_FORM.match(s)
            if m:
                k = float(m["k"]) if m["k"] else 1.0
                d = float(m["d"]) if m["d"] else 1.0
                value = (-1.0 if m["sign"] == "-" else 1.0) * k * np.pi / d
            else:
                value = _plain_number(s)
    except (ValueError, ZeroDivisionError):
        raise InputError(where, text, "expected an angle: radians (0.75, -pi, 3pi/4) or degrees (34deg)") from None
    return _bounded(where, text, value, "angle", "rad")


def parse_length(text, where="length"):
    """A length in m from a plain number (``0.35``) or with a unit (``350mm``, ``0.35m``)."""
    s = str(text).strip().lower()
    scale = 1.0
    for unit, factor in (("mm", 1e-3), ("cm", 1e-2), ("m", 1.0)):
        if s.endswith(unit):
            s, scale = s[: -len(unit)].strip(), factor
            break
    try:
        value = _plain_number(s) * scale
    except ValueError:
        raise InputError(where, text, "expected a length in m (0.35) or with a unit (350mm)") from None
    return _bounded(where, text, value, "length", "m")


def _bounded(where, text, value, what, unit):
    """``value`` as a float if finite and within +-MAX_POSITION_M (in ``unit``)."""
    if not np.isfinite(value):
        raise InputError(where, text, f"must be a finite {what}")
    if abs(value) > MAX_POSITION_M:
        raise InputError(where, text, f"must be within +-{MAX_POSITION_M:g} {unit}")
    return float(value)


def _plain_number(s):
    if not re.fullmatch(_NUMBER, s):
        raise ValueError(s)
    return float(s)
