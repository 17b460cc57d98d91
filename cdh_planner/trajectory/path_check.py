"""Dense verification of the motion between consecutive poses.

What a controller executes between two waypoints is a continuous motion: here position
linear and orientation slerp (``check_motion``), or a straight line in a task's free
coordinates (``check_task_motion``, e.g. the paper's interpolation in the (alpha1, alpha2)
plane). Feasibility along it is checked by **dense sampling**, not by a proof:

1. each segment is sampled uniformly in s in [0, 1] so that consecutive samples are at
   most ``max_step_m`` apart in position and ``max_step_rad`` apart in orientation
   (SO(3) angle), defaults 1 mm and 0.2 deg; a segment needing more than
   MAX_SEGMENT_SAMPLES samples (200 m at 1 mm), or segments needing more than
   MAX_INITIAL_SAMPLES in all, are refused up front (InputError) with the numbers;
2. adaptive refinement: the margin m(s) is estimated to be Lipschitz with constant
   L = the steepest secant slope of the interval and its neighbours; an interval with
   both ends feasible (before the first infeasible sample) is subdivided (8 sub-intervals
   per round, up to 8 rounds, down to 1e-9 in s) whenever a dip below zero is not
   excluded with a safety factor of 2, i.e. when m_a + m_b <= 2 L h;
3. the first unsafe point is located by bisection between the last feasible sample
   before it and the first infeasible one.

A violation narrower than the sampling that the slope estimate does not anticipate can
still be missed; ``SegmentCheck.unresolved`` counts the intervals where the slope test
still allowed a dip when the refinement stopped (0 in the normal case; a motion tangent
to the boundary of C, margin touching 0, is one that sampling cannot decide).
The margin is the normalised one of ``wrench.wrench_feasibility`` (positive iff feasible);
with a scene's collision model (``collision``), the least of it and the collision margin
(``scene.collision.combine``: positive iff also clear of obstacles and other cables).
"""

from collections.abc import Sequence
from dataclasses import dataclass
from typing import Optional

import numpy as np
from ..ports import Rotation

from ..errors import InputError
from ..wrench import wrench_margin
from ..model.pose import rotation_angle_between, rotation_tt
from ..scene.margin import combine

DEFAULT_STEP_M = 1e-3
DEFAULT_STEP_RAD = np.deg2rad(0.2)
SAFETY = 2.0  # factor on the estimated Lipschitz constant of the margin along s
SUBDIVISION = 8  # sub-intervals per flagged interval and refinement round
MAX_ROUNDS = 8
MIN_DS = 1e-9  # do not refine intervals shorter than this (in s)
MAX_SAMPLES = 2_000_000  # budget of evaluated samples per call
MAX_SEGMENT_SAMPLES = 200_000  # a segment needing more initial samples is refused (~2 s)
MAX_INITIAL_SAMPLES = MAX_SAMPLES  # and so are segments needing more in all
BISECTIONS = 40
CHUNK = 20_000  # poses per feasibility call (bounds memory)
SPEED_SAMPLES = 64  # coarse samples per segment to bound the speed of a task line


@dataclass(frozen=True)
class PointCheck:
    """One point of a segment: ``s`` in [0, 1], normalised ``margin`` (-inf if singular),
    ``binding`` constraint name, ``position`` (3,) m, ``quaternion`` (4,) (x, y, z, w)."""

    s: float
    margin: float
    binding: str
    position: np.ndarray
    quaternion: np.ndarray


@dataclass(frozen=True)
class SegmentCheck:
    """The motion from pose ``index_from`` to ``index_to``: ``feasible`` iff every sample
    is; ``worst`` the sample of least margin; ``first_unsafe`` None or the first
    infeasible point (located by bisection); ``samples`` evaluated; ``unresolved``
    intervals the refinement could not settle (see the module docstring)."""

    index_from: int
    index_to: int
    feasible: bool
    worst: PointCheck
    first_unsafe: Optional[PointCheck]
    samples: int
    unresolved: int


def interpolate_segment(p0, q0, p1, q1, s):
    """Poses along one segment: position linear, orientation slerp (shortest arc).

    p0, p1 (3,) m; q0, q1 (4,) quaternions (x, y, z, w); s (M,) in [0, 1].
    Returns positions (M, 3) and quaternions (M, 4) with w >= 0.
    """
    path = SlerpPath(np.array([p0, p1], dtype=float), np.array([q0, q1], dtype=float))
    s = np.atleast_1d(np.asarray(s, dtype=float))
    p, R = path(np.zeros(s.shape, dtype=int), s)
    return p, _quaternions(R)


class SlerpPath:
    """Waypoints joined by linear position and slerp orientation, as scipy's Slerp does:
    r(s) = r0 exp(s log(r0^-1 r1)); evaluated for many segments at once. ``exact_ends``:
    at s = 0 and s = 1 the waypoints themselves (positions as given, rotation matrices
    ``Rotation.from_quat(q).as_matrix()``, bit for bit) rather than the formula's value,
    which differs in the last bits: what lets ``check_path`` reuse the waypoints' margins."""

    def __init__(self, positions, quaternions, exact_ends=False):
        self.positions = np.atleast_2d(positions)
        self.rotations = Rotation.from_quat(np.atleast_2d(quaternions))
        self.rotvecs = (self.rotations[:-1].inv() * self.rotations[1:]).as_rotvec()
        self.n_segments = self.positions.shape[0] - 1
        self.exact_ends = exact_ends

    def __call__(self, seg, s):
        """Positions (M, 3) and rotation matrices (M, 3, 3) at s (M,) of segments seg (M,)."""
        p0, p1 = self.positions[seg], self.positions[seg + 1]
        p = p0 + s[:, None] * (p1 - p0)
        if not self.exact_ends:
            return p, self._slerp(seg, s)
        end, k = waypoint_samples(seg, s)
        inner = np.ones(len(s), dtype=bool)
        inner[end] = False  # the formula only there (row by row: the same numbers)
        R = np.empty((len(s), 3, 3))
        R[inner] = self._slerp(seg[inner], s[inner])
        p[end], R[end] = self.positions[k], self.rotations[k].as_matrix()
        return p, R

    def _slerp(self, seg, s):
        """The formula's rotation matrices (M, 3, 3) at s (M,) of segments seg (M,)."""
        if not len(s):
            return np.empty((0, 3, 3))
        return (self.rotations[seg] * Rotation.from_rotvec(s[:, None] * self.rotvecs[seg])).as_matrix()

    def speeds(self):
        """Per segment: (position change m, rotation angle rad) per unit s (constant)."""
        dp = np.linalg.norm(np.diff(self.positions, axis=0), axis=1)
        return dp, np.linalg.norm(self.rotvecs, axis=1)


class TaskLinePath:
    """Straight lines in a task's free coordinates y (no angle wrapping), mapped to poses
    by ``task.pose``: the motion of a naive interpolation in (alpha1, alpha2) or (phi, theta)."""

    def __init__(self, task, coords):
        self.task = task
        self.coords = np.atleast_2d(np.asarray(coords, dtype=float))
        self.n_segments = self.coords.shape[0] - 1

    def __call__(self, seg, s):
        y0, y1 = self.coords[seg], self.coords[seg + 1]
        p, tau = self.task.pose(y0 + s[:, None] * (y1 - y0))
        return p, rotation_tt(tau)

    def speeds(self):
        """Per segment: the largest position / rotation change per unit s, estimated from
        SPEED_SAMPLES equal steps (the pose map is smooth, so this converges quickly)."""
        k = SPEED_SAMPLES
        seg = np.repeat(np.arange(self.n_segments), k + 1)
        s = np.tile(np.linspace(0.0, 1.0, k + 1), self.n_segments)
        p, R = self(seg, s)
        p = p.reshape(self.n_segments, k + 1, 3)
        R = R.reshape(self.n_segments, k + 1, 3, 3)
        dp = np.linalg.norm(np.diff(p, axis=1), axis=2).max(axis=1) * k
        da = rotation_angle_between(R[:, :-1], R[:, 1:]).max(axis=1) * k
        return dp, da


def check_motion(robot, positions, quaternions, max_step_m=DEFAULT_STEP_M,
                 max_step_rad=DEFAULT_STEP_RAD, collision=None, feasibility=None,
                 waypoints=None):
    """Check the motion through waypoints (positions (N, 3) m, quaternions (N, 4)) with
    position linear and orientation slerp between consecutive ones: the SegmentChecks of
    the N - 1 segments (a sequence of SegmentCheck, also by column). ``waypoints``: None,
    or the waypoints' own ``margin`` (N,) and ``binding`` (N,) as ``feasibility`` and
    ``collision`` (``combine``) give them at (positions, ``Rotation.from_quat(quaternions)
    .as_matrix()``): the samples at s = 0 and 1 are those poses, so they take these rather
    than being evaluated again (``verify`` has them already)."""
    path = SlerpPath(np.asarray(positions, dtype=float), np.asarray(quaternions, dtype=float),
                     exact_ends=waypoints is not None)
    return check_path(robot, path, max_step_m, max_step_rad, collision, feasibility, waypoints)


def check_task_motion(robot, task, coords, max_step_m=DEFAULT_STEP_M,
                      max_step_rad=DEFAULT_STEP_RAD):
    """Check straight lines between consecutive task coordinates (N, k): N - 1 SegmentChecks."""
    return check_path(robot, TaskLinePath(task, coords), max_step_m, max_step_rad)


def check_path(robot, path, max_step_m=DEFAULT_STEP_M, max_step_rad=DEFAULT_STEP_RAD,
               collision=None, feasibility=None, waypoints=None):
    """Dense check of every segment of ``path`` (SlerpPath, TaskLinePath or alike:
    ``path(seg, s) -> (p, R)``, ``path.speeds()``, ``path.n_segments``); ``collision``: a
    scene's CollisionModel or None; ``feasibility(robot, p, R=R)``: the margin checked, a
    record with ``margin`` and ``binding`` (default ``wrench_margin``, the exact test's; the
    planner's is ``band_feasibility``); ``waypoints``: None, or the margins and bindings
    (a record, n_segments + 1 each) of the poses at s = 0 and 1, taken for those samples
    (the path must be the waypoints there: ``SlerpPath(exact_ends=True)``). Returns the
    SegmentChecks of the segments."""
    if waypoints is not None and not getattr(path, "exact_ends", False):
        raise ValueError("check_path: waypoint margins need a path exact at its ends")
    samples = _Samples(robot, path, collision, feasibility or wrench_margin, waypoints)
    if path.n_segments < 1:
        return _segment_results(samples, {}, np.zeros(0, dtype=int))
    samples.add(*_initial_grid(path, max_step_m, max_step_rad))
    unresolved = _refine(samples)
    first = _first_unsafe(samples)
    return _segment_results(samples, first, unresolved)


def _initial_grid(path, max_step_m, max_step_rad):
    """Uniform s grids with steps below max_step_m / max_step_rad along each segment.
    InputError, before anything is allocated, when a segment needs more than
    MAX_SEGMENT_SAMPLES samples or all of them more than MAX_INITIAL_SAMPLES."""
    dp, da = path.speeds()
    with np.errstate(divide="ignore", invalid="ignore", over="ignore"):
        need = np.maximum(dp / max_step_m, da / max_step_rad)
    need = np.where(np.isnan(need), np.inf, need)
    worst = int(np.argmax(need)) if need.size else 0
    if need.size and not need[worst] <= MAX_SEGMENT_SAMPLES:
        raise InputError(f"segment {worst} -> {worst + 1}", f"{need[worst]:.3g} samples",
                         f"over the {MAX_SEGMENT_SAMPLES} samples of one segment ({dp[worst]:.3g} m, "
                         f"{da[worst]:.3g} rad at steps of {max_step_m:.3g} m, {max_step_rad:.3g} rad): "
                         "add poses between, or use a larger step")
    n = np.maximum(1, np.ceil(need)).astype(int)
    if int(np.sum(n + 1)) > MAX_INITIAL_SAMPLES:
        raise InputError("segments", f"{int(np.sum(n + 1))} samples",
                         f"over the {MAX_INITIAL_SAMPLES} samples of one check: use a larger "
                         "step or fewer poses")
    seg = np.repeat(np.arange(path.n_segments), n + 1)
    start = np.repeat(np.cumsum(n + 1) - (n + 1), n + 1)
    s = (np.arange(seg.size) - start) / np.repeat(n, n + 1)
    return seg, s


def waypoint_samples(seg, s):
    """The samples (seg (M,), s (M,)) at a segment's ends: their indices, and the indices
    of the waypoints they are (seg at s = 0, seg + 1 at s = 1)."""
    end = np.flatnonzero((s == 0.0) | (s == 1.0))
    return end, seg[end] + (s[end] == 1.0)


class _Samples:
    """Evaluated samples of all segments, kept sorted by (segment, s); ``waypoints``: None
    or the known margins and bindings of the segments' ends (``check_path``)."""

    def __init__(self, robot, path, collision=None, feasibility=wrench_margin, waypoints=None):
        self.robot, self.path, self.collision = robot, path, collision
        self.feasibility, self.waypoints = feasibility, waypoints
        # the waypoints' bindings as the samples hold them (Python strings), made once:
        # each of them ends two segments (20,000 strings made again each time were 3 ms)
        self.waypoint_binding = (None if waypoints is None
                                 else np.asarray(waypoints.binding, dtype=object))
        self.seg = np.empty(0, dtype=int)
        self.s = np.empty(0)
        self.margin = np.empty(0)
        self.binding = np.empty(0, dtype=object)

    def evaluate(self, seg, s):
        """Margins and binding constraints at (seg, s), in chunks to bound memory."""
        margin, binding = np.empty(s.size), np.empty(s.size, dtype=object)
        todo = np.ones(s.size, dtype=bool)
        if self.waypoints is not None:  # the ends are waypoints: their values are known
            end, k = waypoint_samples(seg, s)
            margin[end], binding[end] = self.waypoints.margin[k], self.waypoint_binding[k]
            todo[end] = False
        todo = np.flatnonzero(todo)
        for a in range(0, todo.size, CHUNK):
            i = todo[a:a + CHUNK]
            p, R = self.path(seg[i], s[i])
            f = self.feasibility(self.robot, p, R=R)
            margin[i], binding[i] = combine(f.margin, f.binding, self.collision, p, R)
        return np.where(np.isnan(margin), -np.inf, margin), binding

    def add(self, seg, s):
        margin, binding = self.evaluate(seg, s)
        if not self.s.size and _in_order(seg, s):  # the initial grid: nothing to merge or sort
            self.seg, self.s, self.margin, self.binding = seg, s, margin, binding
            return
        self.seg = np.concatenate([self.seg, seg])
        self.s = np.concatenate([self.s, s])
        self.margin = np.concatenate([self.margin, margin])
        self.binding = np.concatenate([self.binding, binding])
        order = np.lexsort((self.s, self.seg))
        self.seg, self.s = self.seg[order], self.s[order]
        self.margin, self.binding = self.margin[order], self.binding[order]


def _in_order(seg, s):
    """Whether samples (seg, s) are in strictly increasing (segment, s) order: the order
    ``_Samples.add``'s lexsort gives them."""
    step = np.diff(seg)
    return bool(np.all((step > 0) | ((step == 0) & (np.diff(s) > 0))))


def _refine(samples):
    """Subdivide intervals where the margin might dip below zero; returns, per segment,
    the number of such intervals left when the budget or MIN_DS stopped the refinement."""
    n_seg = samples.path.n_segments
    for _ in range(MAX_ROUNDS):
        doubtful, ratio, h = _doubtful_intervals(samples)
        keep = h > MIN_DS
        doubtful, ratio = doubtful[keep], ratio[keep]
        budget = (MAX_SAMPLES - samples.s.size) // (SUBDIVISION - 1)
        if not doubtful.size or budget <= 0:
            break
        # Most doubtful first when the budget does not cover every interval.
        doubtful = doubtful[np.argsort(ratio)][:budget]
        s_a = samples.s[doubtful]
        step = samples.s[doubtful + 1] - s_a
        frac = np.arange(1, SUBDIVISION) / SUBDIVISION
        samples.add(np.repeat(samples.seg[doubtful], SUBDIVISION - 1),
                    (s_a[:, None] + step[:, None] * frac).ravel())
    doubtful, _, _ = _doubtful_intervals(samples)
    return np.bincount(samples.seg[doubtful], minlength=n_seg)


def _doubtful_intervals(samples):
    """Intervals [i, i + 1] before the first infeasible sample of their segment, with both
    ends feasible, where the margin, if Lipschitz with SAFETY times the local secant slope,
    could reach zero inside. Returns their indices i, the ratios (m_a + m_b) / (SAFETY L h)
    (below 1) and their lengths h in s."""
    m, s, seg = samples.margin, samples.s, samples.seg
    same = seg[1:] == seg[:-1]
    h = np.where(same, s[1:] - s[:-1], np.inf)
    with np.errstate(invalid="ignore", over="ignore"):  # -inf margins at singular samples
        dm = np.abs(np.diff(m))
        slope = np.where(same & np.isfinite(dm), dm / np.where(h > 0, h, np.inf), 0.0)
    # Neighbours' slopes too: a dip between samples shows as steep secants next to it.
    L = slope.copy()
    L[1:] = np.maximum(L[1:], np.where(same[:-1], slope[:-1], 0.0))
    L[:-1] = np.maximum(L[:-1], np.where(same[1:], slope[1:], 0.0))
    # Past the first infeasible sample the segment is unsafe anyway: nothing to refine.
    bad_so_far = _count_within_segments(m <= 0, seg)
    bound = SAFETY * L * np.where(same, h, 0.0)  # (h is inf between segments)
    doubtful = same & (bad_so_far[1:] == 0) & (m[:-1] + m[1:] <= bound)
    idx = np.flatnonzero(doubtful)
    return idx, (m[idx] + m[idx + 1]) / np.maximum(bound[idx], 1e-300), h[idx]


def _count_within_segments(flags, seg):
    """Running count of True flags from the start of each segment (seg sorted)."""
    cum = np.cumsum(flags)
    starts = np.flatnonzero(np.r_[True, seg[1:] != seg[:-1]])
    before = cum[starts] - flags[starts]
    return cum - np.repeat(before, np.diff(np.r_[starts, seg.size]))


def _first_unsafe(samples):
    """{segment: (s, margin, binding)} of the first infeasible point of each unsafe segment."""
    bad = samples.margin <= 0
    seg_bad = samples.seg[bad]
    if not seg_bad.size:
        return {}
    segs, first_pos = np.unique(seg_bad, return_index=True)
    j = np.flatnonzero(bad)[first_pos]
    at_start = (j == 0) | (samples.seg[np.maximum(j - 1, 0)] != samples.seg[j])
    lo = np.where(at_start, samples.s[j], samples.s[np.maximum(j - 1, 0)])
    hi = samples.s[j].copy()
    m_hi, b_hi = samples.margin[j].copy(), samples.binding[j].copy()
    todo = ~at_start
    for _ in range(BISECTIONS):
        if not todo.any():
            break
        mid = 0.5 * (lo[todo] + hi[todo])
        m, b = samples.evaluate(segs[todo], mid)
        idx = np.flatnonzero(todo)
        unsafe = m <= 0
        hi[idx[unsafe]], m_hi[idx[unsafe]], b_hi[idx[unsafe]] = mid[unsafe], m[unsafe], b[unsafe]
        lo[idx[~unsafe]] = mid[~unsafe]
    return {int(k): (hi[i], m_hi[i], b_hi[i]) for i, k in enumerate(segs)}


def _segment_results(samples, first, unresolved):
    """The SegmentChecks of every segment; the worst and first unsafe points of all
    segments are evaluated in one call each (linear in the number of segments)."""
    n = samples.path.n_segments
    bounds = np.searchsorted(samples.seg, np.arange(n + 1))
    i = _least_in_segments(samples.margin, bounds)
    worst = _points(samples, np.arange(n), samples.s[i], samples.margin[i], samples.binding[i])
    segs = np.array(sorted(first), dtype=int)
    unsafe = _points(samples, segs, *(np.array([first[k][j] for k in segs.tolist()])
                                      for j in range(3)))
    feasible = np.ones(n, dtype=bool)
    feasible[segs] = False
    return SegmentChecks(feasible=feasible, worst=worst, unsafe_index=segs, unsafe=unsafe,
                         samples=np.diff(bounds), unresolved=np.asarray(unresolved))


def _least_in_segments(margin, bounds):
    """The index of the least ``margin`` of each segment (samples bounds[j] <= i <
    bounds[j + 1]; none empty, no nan: a segment has its ends, evaluate gives -inf for
    nan), the first on ties: what sorting by (segment, margin, index) puts first."""
    if len(bounds) < 2:
        return np.empty(0, dtype=int)
    least = np.minimum.reduceat(margin, bounds[:-1])
    at_least = np.flatnonzero(margin == np.repeat(least, np.diff(bounds)))
    return at_least[np.searchsorted(at_least, bounds[:-1])]


@dataclass(frozen=True)
class PointChecks:
    """Points of several segments by column: ``s`` (M,), ``margin`` (M,), ``binding`` (M,)
    str, ``position`` (M, 3) m, ``quaternion`` (M, 4) (x, y, z, w); ``[k]`` is a PointCheck."""

    s: np.ndarray
    margin: np.ndarray
    binding: list
    position: np.ndarray
    quaternion: np.ndarray

    def __len__(self):
        return len(self.s)

    def __getitem__(self, k):
        return PointCheck(s=float(self.s[k]), margin=float(self.margin[k]),
                          binding=self.binding[k], position=self.position[k],
                          quaternion=self.quaternion[k])


class SegmentChecks(Sequence):
    """The checks of segments 0 -> 1, 1 -> 2, ... by column (what a bulk report reads
    without a Python object per segment); ``[k]`` is segment k's SegmentCheck.
    ``feasible`` (n,) bool, ``worst`` PointChecks (n), ``unsafe`` PointChecks of the
    first unsafe points of the segments ``unsafe_index`` (ascending), ``samples`` and
    ``unresolved`` (n,) int."""

    def __init__(self, feasible, worst, unsafe_index, unsafe, samples, unresolved):
        self.feasible, self.worst, self.samples, self.unresolved = (feasible, worst, samples,
                                                                    unresolved)
        self.unsafe_index, self.unsafe = unsafe_index, unsafe

    def __len__(self):
        return len(self.feasible)

    def __getitem__(self, k):
        if isinstance(k, slice):
            return [self[j] for j in range(*k.indices(len(self)))]
        k = range(len(self))[k]  # negative indices; IndexError past the end
        at = int(np.searchsorted(self.unsafe_index, k))
        unsafe = (self.unsafe[at] if at < len(self.unsafe_index) and self.unsafe_index[at] == k
                  else None)
        return SegmentCheck(index_from=k, index_to=k + 1, feasible=bool(self.feasible[k]),
                            worst=self.worst[k], first_unsafe=unsafe,
                            samples=int(self.samples[k]), unresolved=int(self.unresolved[k]))


def _points(samples, segs, s, margin, binding):
    """PointChecks at s (M,) of segments ``segs`` (M,)."""
    s = np.asarray(s, dtype=float).reshape(-1)
    margin = np.asarray(margin, dtype=float).reshape(-1)
    if not len(segs):
        return PointChecks(s, margin, [], np.empty((0, 3)), np.empty((0, 4)))
    p, R = samples.path(segs, s)
    return PointChecks(s, margin, [str(b) for b in binding], p, _quaternions(R))


def _quaternions(R):
    """Quaternions (M, 4), w >= 0, of the paths' rotation matrices (M, 3, 3): products of
    rotations' formulas, orthogonal to rounding, so not checked (``assume_valid``)."""
    q = Rotation.from_matrix(R, assume_valid=True).as_quat()
    return np.where(q[:, 3:4] < 0, -q, q)
