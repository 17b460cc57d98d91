"""A plan run on the simulated robot, recorded, and what the run says (no rclpy).

    plan = read_plan(path, robot)                 # the plan JSON's published trajectory
    record = run_plan(robot, plan, scene)         # settled at the start, run, held at the end
    report = judge(robot, plan, record, scene)    # margins, slack, overload, tracking, contacts

The commands are the plan's ``commanded_lengths`` (the unstretched lengths that carry the
nominal tensions, with ``velocities`` / ``accelerations`` their rates) where the JSON has
them, else its ``lengths``; a JointTrajectoryController interpolates them
(``commands.Trajectory``: the quintic of positions, velocities and accelerations). Before
the motion the plant holds the first command for SETTLE_S (a robot rests at its start
before it executes; not recorded), after it the last for TAIL_S (recorded).

Verdicts (``Report``), per cable: the least margin (N) of the measured tension against
the robot's limits, min(t - tension_min, tension_max - t), and, during the motion (first
to last waypoint), against the published envelope (tension_min .. tension_max per
waypoint, linear in time between waypoints); the time (s) slack (tension 0), below the least tension and above the
greatest; the measured cable lengths against the length limits; the tracking error
(platform pose against the plan's at each waypoint's time); contacts with obstacles: the
platform's from MuJoCo, every cable's from the scene's collision model at the measured
poses (MuJoCo's tendons pass through geoms) every CONTACT_EVERY samples. ``ok``: no limit
left (tensions within TOL_N of their limits, lengths within theirs, no contact).
"""

from dataclasses import dataclass, field

import numpy as np

from ..errors import InputError
from ..model.pose import rotation_angle_between, rotation_from_quaternion
from .commands import Trajectory
from .mjcf import TIMESTEP_S

SETTLE_S = 1.0          # s: the first command held before the motion (not recorded)
TAIL_S = 0.5            # s: the last command held after the motion (recorded)
TOL_N = 1e-9            # N: rounding allowed against a tension limit
CONTACT_EVERY = 10      # samples between collision checks of the measured poses (10 ms)
MAX_DURATION_S = 3600.0  # s: a longer plan is refused (3.6e6 steps)
WAYPOINT_KEYS = ("t", "p", "quaternion", "lengths", "tension_min", "tension_max")


@dataclass
class Plan:
    """The published trajectory: waypoint times (N,) s, poses p (N, 3) m and quaternions
    (N, 4), the commanded lengths L (N, m) m with rates V, A (or None: positions only),
    the envelope low / nominal / high (N, m) N; ``source``: the JSON key of L."""
    t: np.ndarray
    p: np.ndarray
    quaternion: np.ndarray
    L: np.ndarray
    V: np.ndarray
    A: np.ndarray
    low: np.ndarray
    nominal: np.ndarray
    high: np.ndarray
    source: str = "lengths"


def read_plan(path, robot):
    """The Plan of a plan JSON file (``cdh-planner plan --json``) for ``robot``; InputError
    naming the file or the field when it is not a successful plan of this robot's cables."""
    from ..files import read_json
    doc = read_json(path, "PLAN")
    if not isinstance(doc, dict) or not isinstance(doc.get("path"), list) or not doc["path"]:
        raise InputError("PLAN", str(path), "not a plan JSON with a path (cdh-planner plan --json)")
    return plan_from_waypoints(doc["path"], len(robot.base_anchors))


def plan_from_waypoints(path, m):
    """The Plan of the JSON waypoints ``path`` (list of dicts) of an m-cable robot."""
    key = "commanded_lengths" if all("commanded_lengths" in w for w in path) else "lengths"
    cols = {k: _column(path, k, m) for k in (*WAYPOINT_KEYS, key, "tension_nominal",
                                             "velocities", "accelerations")}
    t = cols["t"][:, 0]
    if np.any(np.diff(t) <= 0) or t[-1] - t[0] > MAX_DURATION_S:
        raise InputError("path[].t", f"{t[0]:g} .. {t[-1]:g}",
                         f"waypoint times must increase, over at most {MAX_DURATION_S:g} s")
    if np.any(cols[key] <= 0):
        raise InputError(f"path[].{key}", float(np.min(cols[key])), "lengths must be positive")
    nominal = cols["tension_nominal"]
    return Plan(t=t - t[0], p=cols["p"], quaternion=_unit(cols["quaternion"]), L=cols[key],
                V=cols["velocities"], A=cols["accelerations"], low=cols["tension_min"],
                nominal=0.5 * (cols["tension_min"] + cols["tension_max"]) if nominal is None else nominal,
                high=cols["tension_max"], source=key)


def _column(path, key, m):
    """The waypoints' ``key`` as an array (N, size); None for an optional key absent from all."""
    size = {"t": 1, "p": 3, "quaternion": 4}.get(key, m)
    optional = key in ("tension_nominal", "velocities", "accelerations")
    if optional and not any(isinstance(w, dict) and key in w for w in path):
        return None
    rows = []
    for i, w in enumerate(path):
        value = w.get(key) if isinstance(w, dict) else None
        value = [value] if size == 1 and not isinstance(value, list) else value
        if not isinstance(value, list) or len(value) != size or not all(
                isinstance(x, (int, float)) and not isinstance(x, bool) and np.isfinite(x)
                for x in value):
            raise InputError(f"path[{i}].{key}", value, f"expected {size} finite numbers "
                                                        f"({m} cables)" if size == m else
                             f"expected {size} finite numbers")
        rows.append(value)
    return np.array(rows, dtype=float)


def _unit(q):
    n = np.linalg.norm(q, axis=1)
    if np.any(np.abs(n - 1.0) > 1e-3):
        raise InputError("path[].quaternion", q[np.argmax(np.abs(n - 1.0))].tolist(),
                         "not a unit quaternion")
    return q / n[:, None]


# ----------------------------------------------------------------------------- running

@dataclass
class Record:
    """Time series of a run, one row per control period: ``t`` (M,) s; the commanded
    (winch) lengths, the measured tensions and cable lengths (M, m); the platform's p (M, 3)
    m and quaternion (M, 4) (x, y, z, w); ``contacts``: (time s, obstacle id) of each
    platform contact MuJoCo reported."""
    t: np.ndarray
    winch: np.ndarray
    tension: np.ndarray
    length: np.ndarray
    p: np.ndarray
    quaternion: np.ndarray
    contacts: list = field(default_factory=list)
    substeps: int = 1


def run(plant, command, duration, on_step=None):
    """Step ``plant`` for ``duration`` s under ``command`` (commands.Trajectory, its times
    on the plant's clock) and record each period: the state and command at its start, the
    tensions applied during it. ``on_step(k, plant)`` is called after each step."""
    steps = int(round(duration / TIMESTEP_S))
    ts = plant.time + TIMESTEP_S * np.arange(steps)
    L0, rate = command.sample(ts)
    m = plant.m
    rec = Record(t=ts, winch=L0, tension=np.empty((steps, m)), length=np.empty((steps, m)),
                 p=np.empty((steps, 3)), quaternion=np.empty((steps, 4)), substeps=plant.substeps)
    for k in range(steps):
        plant.command(L0[k], rate[k])
        rec.p[k], rec.quaternion[k] = plant.pose()
        plant.step()
        rec.tension[k], rec.length[k] = plant.tensions, plant.data.ten_length
        if plant.data.ncon:
            rec.contacts += [(float(ts[k]), o) for o in plant.contacts()]
        if on_step is not None:
            on_step(k, plant)
    return rec


def run_plan(robot, plan, scene=None, settle_s=SETTLE_S, tail_s=TAIL_S, plant=None):
    """Run ``plan`` (Plan) on a SimulatedRobot of ``robot`` (and ``scene``): placed at the
    first waypoint's pose at rest, the first command held ``settle_s``, then the trajectory
    and ``tail_s`` of the last command, recorded (Record, t = 0 at the first waypoint)."""
    from .plant import SimulatedRobot
    plant = plant or SimulatedRobot(robot, scene)
    plant.reset(plan.p[0], plan.quaternion[0], plan.L[0])
    command = Trajectory(plan.t, plan.L, plan.V, plan.A)
    if settle_s > 0:
        plant.time = -settle_s
        run(plant, command, settle_s)
    plant.time = 0.0
    return run(plant, command, plan.t[-1] + tail_s)


# ----------------------------------------------------------------------------- verdicts

@dataclass
class Report:
    """What a run says; tensions in N, times in s, lengths in m, angles in rad. Per cable
    (m,): ``limit_margin`` and ``envelope_margin`` (least, N; negative: left),
    ``limit_margin_fraction`` (of the tension range), ``slack_s``, ``below_min_s``,
    ``overload_s``, ``length_out_s``; ``tension_low`` / ``tension_high`` measured extremes;
    ``tracking_position_m`` / ``tracking_orientation_rad`` (largest at the waypoints);
    ``contacts``: {obstacle id or "winch_i / id": first time s}; ``ok``: no limit left."""
    names: tuple
    limit_margin: np.ndarray
    limit_margin_fraction: np.ndarray
    envelope_margin: np.ndarray
    envelope_margin_fraction: np.ndarray
    slack_s: np.ndarray
    below_min_s: np.ndarray
    overload_s: np.ndarray
    length_out_s: np.ndarray
    tension_low: np.ndarray
    tension_high: np.ndarray
    tracking_position_m: float
    tracking_orientation_rad: float
    contacts: dict
    duration_s: float
    commands: str

    @property
    def ok(self):
        return bool(np.all(self.limit_margin >= -TOL_N) and not np.any(self.length_out_s)
                    and not self.contacts)


def envelope_at(plan, ts):
    """The published envelope (low, high), each (M, m) N, at times ``ts``: linear in time
    between waypoints, held beyond the ends."""
    low = np.stack([np.interp(ts, plan.t, plan.low[:, i]) for i in range(plan.low.shape[1])], 1)
    high = np.stack([np.interp(ts, plan.t, plan.high[:, i]) for i in range(plan.high.shape[1])], 1)
    return low, high


def judge(robot, plan, record, scene=None):
    """The Report of ``record`` (Record) of ``plan`` on ``robot`` (``scene``: obstacles)."""
    f, dt = record.tension, TIMESTEP_S
    fmin, fmax = np.asarray(robot.tension_min, float), np.asarray(robot.tension_max, float)
    span = fmax - fmin
    limit = np.min(np.minimum(f - fmin, fmax - f), axis=0)
    motion = record.t <= plan.t[-1]     # the envelope is published for the motion
    low, high = envelope_at(plan, record.t[motion])
    env = np.min(np.minimum(f[motion] - low, high - f[motion]), axis=0)
    lengths_out = (record.length < robot.length_min) | (record.length > robot.length_max)
    pos, rot = tracking(plan, record)
    return Report(names=tuple(robot.winch_names), limit_margin=limit,
                  limit_margin_fraction=limit / span, envelope_margin=env,
                  envelope_margin_fraction=env / span,
                  slack_s=np.sum(f <= 0.0, axis=0) * dt, below_min_s=np.sum(f < fmin - TOL_N, axis=0) * dt,
                  overload_s=np.sum(f > fmax + TOL_N, axis=0) * dt,
                  length_out_s=np.sum(lengths_out, axis=0) * dt, tension_low=f.min(axis=0),
                  tension_high=f.max(axis=0), tracking_position_m=pos, tracking_orientation_rad=rot,
                  contacts=contacts(robot, record, scene), duration_s=float(len(f) * dt),
                  commands=plan.source)


def tracking(plan, record):
    """The largest distance (m) and rotation (rad) between the measured platform and the
    plan's pose at each waypoint's time (the nearest sample)."""
    k = np.clip(np.searchsorted(record.t, plan.t - 0.5 * TIMESTEP_S), 0, len(record.t) - 1)
    pos = float(np.max(np.linalg.norm(record.p[k] - plan.p, axis=1)))
    rot = rotation_angle_between(rotation_from_quaternion(record.quaternion[k]),
                                 rotation_from_quaternion(plan.quaternion))
    return pos, float(np.max(rot))


def contacts(robot, record, scene):
    """{what: first time (s)}: the platform's contacts (MuJoCo) and the cables' and
    platform's (the scene's collision model, negative distance) at the measured poses."""
    out = {}
    for t, o in record.contacts:
        out.setdefault(f"platform / {o}", t)
    if scene is None or not scene.obstacles:
        return out
    from ..scene.collision import CollisionModel
    model = CollisionModel(robot, scene)
    R = rotation_from_quaternion(record.quaternion[::CONTACT_EVERY])
    for t, p, Rk in zip(record.t[::CONTACT_EVERY], record.p[::CONTACT_EVERY], R):
        for kind, oid, cables, d in model.distances(p, Rk):
            if d < 0 and kind in ("cable-obstacle", "platform-obstacle"):
                who = robot.winch_names[cables[0]] if cables else "platform"
                out.setdefault(f"{who} / {oid}", float(t))
    return out
