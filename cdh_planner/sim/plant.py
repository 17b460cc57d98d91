"""The simulated robot: MuJoCo stepped at 1 kHz under a command of unstretched cable lengths,
measured as a robot's sensors would (no rclpy).

    plant = SimulatedRobot(robot, scene=None)
    plant.reset(p, quaternion, L0)           # the platform at rest at a pose, winches at L0
    plant.command(L0, L0_rate)               # each winch's unstretched length (m), m/s
    plant.step()                             # one control period (TIMESTEP_S, 1 ms)
    plant.tensions, plant.winch_positions, plant.pose(), plant.lengths, plant.contacts()

A winch is a perfect position servo: its position is the commanded unstretched length L0
(m). Cable i is a tension-only spring of stiffness k = EA / L0 with damping kv =
DAMPING_TIME_S k on the stretch rate: its tension is max(0, k (L - L0) + kv (L' - L0'))
(``sim.mjcf``: ctrl = L0 + DAMPING_TIME_S L0', gains set for the commanded L0 every step).

The load cells (``tensions``, N) read what MuJoCo applied during the last step, as measured
on this MuJoCo (4.0.1) against the platform's change of momentum (to 6e-14 N):
``actuator_force`` is computed before the step at the old velocity, while ``implicitfast``
applies the damping at the new one, so kv J (v_new - v_old) is added (J the tendon
Jacobian before the step), except where the force is clamped at 0 (a slack cable: MuJoCo
then applies no damping). Forces are read after ``mj_step`` (a second ``mj_forward`` would
mix two times). The stiffness is explicit in every integrator: where sqrt(k / m) dt is
large the plant takes ``substeps`` MuJoCo steps per control period (``substeps``).

A load moment or a wrench ellipsoid offset (what gravity on the load mass does not give)
is applied as an external wrench on the platform at every step.
"""

import math

import numpy as np

from ..wrench import nominal_wrench, rule_tensions
from .mjcf import DAMPING_TIME_S, TIMESTEP_S, cable_stiffness, load_mass, mjcf

OMEGA_DT = 0.5            # largest (natural frequency x MuJoCo step) allowed
MAX_SUBSTEPS = 64


GL_FAILURE = []           # why mujoco's OpenGL backend did not load (then disabled)


def _mujoco():
    """The mujoco module. With MUJOCO_GL naming a backend whose library is absent, ``import
    mujoco`` itself fails (PyOpenGL raises while loading): then the backend is disabled
    (MUJOCO_GL=disable), the physics imported without it, and why kept in GL_FAILURE (the
    rendering says so in one line)."""
    import os
    import sys
    try:
        import mujoco
    except ImportError as exc:
        if exc.name == "mujoco":
            raise
        failure = exc
    except Exception as exc:   # noqa: BLE001 - PyOpenGL's AttributeError without its library
        failure = exc
    else:
        return mujoco
    for name in [n for n in sys.modules if n.split(".")[0] in ("mujoco", "OpenGL")]:
        del sys.modules[name]
    GL_FAILURE.append(f"MUJOCO_GL={os.environ.get('MUJOCO_GL', '')}: {type(failure).__name__}: "
                      f"{str(failure).splitlines()[0] if str(failure) else ''}")
    os.environ["MUJOCO_GL"] = "disable"
    import mujoco
    return mujoco


def rest_lengths(robot, p, R):
    """The winch lengths (m,) m at which the platform rests at pose (p (3,) m, R (3, 3)):
    the unstretched lengths that carry the tension rule's nominal tensions there,
    L0 = L / (1 + t / EA) (the plant's stiffness, ``mjcf.cable_stiffness``)."""
    from ..model.kinematics import cable_lengths
    t = rule_tensions(robot, np.asarray(p, float)[None], np.asarray(R, float)[None])[0][0]
    return cable_lengths(robot, p, R) / (1.0 + t / cable_stiffness(robot))


class SimulatedRobot:
    """MuJoCo's model of ``robot`` (model.robot.Robot) and ``scene`` (obstacles), stepped at
    TIMESTEP_S under a length command. Time ``time`` (s) counts control periods."""

    def __init__(self, robot, scene=None):
        mj = _mujoco()
        self.robot = robot
        self.model = mj.MjModel.from_xml_string(mjcf(robot, scene))
        self.data = mj.MjData(self.model)
        self.m = len(robot.base_anchors)
        self.EA = cable_stiffness(robot)
        self.mass = load_mass(robot)
        self.body = self.model.body("platform").id
        self.obstacle_geoms = {self.model.geom(g).id: self.model.geom(g).name.removeprefix("obstacle_")
                               for g in range(self.model.ngeom)
                               if self.model.geom(g).name.startswith("obstacle_")}
        self.winch_positions = np.zeros(self.m)
        self.tensions = np.zeros(self.m)
        self.substeps = 1
        self.time = 0.0
        self._extra = self._needs_extra_wrench()

    # ------------------------------------------------------------------ state and command

    def reset(self, p, quaternion, L0):
        """The platform at rest at (p (3,) m, quaternion (x, y, z, w)), the winches at L0 (m,)
        m; time 0; substeps set for the stiffness there. Tensions are those of the pose."""
        mj = _mujoco()
        mj.mj_resetData(self.model, self.data)
        q = np.asarray(quaternion, dtype=float)
        self.data.qpos[:7] = np.concatenate([p, [q[3], q[0], q[1], q[2]]])
        self.command(L0, np.zeros(self.m))
        mj.mj_forward(self.model, self.data)
        self.tensions = np.maximum(self.data.actuator_force, 0.0).copy()
        self.time = 0.0
        self.substeps = self._substeps()
        self.model.opt.timestep = TIMESTEP_S / self.substeps

    def command(self, L0, rate):
        """Winch i to unstretched length L0[i] (m) moving at rate[i] (m/s)."""
        L0 = np.asarray(L0, dtype=float)
        k = self.EA / L0
        self.model.actuator_gainprm[:, 0] = -k
        self.model.actuator_biasprm[:, 1] = -k
        self.model.actuator_biasprm[:, 2] = -DAMPING_TIME_S * k
        self.data.ctrl[:] = L0 + DAMPING_TIME_S * np.asarray(rate, dtype=float)
        self.winch_positions = L0.copy()

    def _substeps(self):
        """MuJoCo steps per control period keeping sqrt(k / m) dt <= OMEGA_DT: the largest
        natural frequency of the platform on its cables (generalised eigenvalues of
        J^T diag(k) J against the mass matrix) at the current pose."""
        mj = _mujoco()
        nv = self.model.nv
        M = np.zeros((nv, nv))
        mj.mj_fullM(self.model, self.data, M)
        J = self.data.ten_J.reshape(self.m, nv)
        K = J.T @ (-self.model.actuator_gainprm[:, 0, None] * J)
        omega = math.sqrt(max(float(np.max(np.linalg.eigvals(np.linalg.solve(M, K)).real)), 0.0))
        return int(min(MAX_SUBSTEPS, max(1, math.ceil(omega * TIMESTEP_S / OMEGA_DT))))

    # ------------------------------------------------------------------ stepping

    def step(self):
        """One control period: ``substeps`` MuJoCo steps under the current command; then the
        load cells hold the tensions applied during the last one (N)."""
        mj = _mujoco()
        d, nv = self.data, self.model.nv
        kv = -self.model.actuator_biasprm[:, 2]
        for _ in range(self.substeps):
            if self._extra:
                self._apply_extra_wrench()
            J = d.ten_J.reshape(self.m, nv).copy()
            v_old = d.qvel.copy()
            mj.mj_step(self.model, d)
            force = d.actuator_force
            self.tensions = np.where(force > 0.0, force + kv * (J @ (d.qvel - v_old)), 0.0)
        self.time += TIMESTEP_S

    def _needs_extra_wrench(self):
        r = self.robot
        return bool(np.any(r.moment) or np.any(r.ellipsoid_offset))

    def _apply_extra_wrench(self):
        """What gravity on the mass does not give of the load wrench w0 (force; moment about
        the base origin, ``wrench.nominal_wrench``), at the centre of mass c."""
        c = self.data.xipos[self.body].copy()
        w = nominal_wrench(self.robot, c[None])[0]
        force = w[:3] - self.mass * self.model.opt.gravity
        self.data.xfrc_applied[self.body] = np.concatenate([force, w[3:] - np.cross(c, w[:3])])

    # ------------------------------------------------------------------ sensors

    def pose(self):
        """The platform's pose (tracker): p (3,) m and quaternion (x, y, z, w)."""
        q = self.data.qpos[3:7]
        return self.data.qpos[:3].copy(), np.array([q[1], q[2], q[3], q[0]])

    def rotation(self):
        """The platform's rotation matrix (3, 3), base frame, now (from qpos: MuJoCo's xmat
        is of the last step's start)."""
        from ..model.pose import rotation_from_quaternion
        return rotation_from_quaternion(self.pose()[1])

    @property
    def lengths(self):
        """The cables' lengths L (m,) m, anchor to anchor, at the last step's start: the
        state the load cells' ``tensions`` belong to."""
        return self.data.ten_length.copy()

    def contacts(self):
        """The obstacles (ids) the platform touches now (MuJoCo's contacts)."""
        n = self.data.ncon
        geoms = np.concatenate([self.data.contact.geom1[:n], self.data.contact.geom2[:n]])
        return {self.obstacle_geoms[int(g)] for g in geoms if int(g) in self.obstacle_geoms}
