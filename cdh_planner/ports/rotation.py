"""Rotations as unit quaternions (x, y, z, w), in numpy alone: the part of scipy's
``scipy.spatial.transform.Rotation`` the planner uses, with scipy's formulas and its
branch points, so that answers agree with scipy's to rounding (test_rotation_splines.py).

Why not scipy's: importing ``scipy.spatial`` runs its package ``__init__`` (k-d trees,
Qhull, distances, scipy.sparse: about 0.17 s of a 0.55 s plan); a direct-motion
plan needs none of it. Only stacks of rotations (N, 4) and single ones.

    r = Rotation.from_matrix(R)     # (N, 3, 3) or (3, 3)
    (r[:-1].inv() * r[1:]).as_rotvec()
"""

import numpy as np

SMALL_ANGLE = 1e-3  # rad: below it scipy's Taylor series replace sin(a / 2) / a and its inverse


def _norm(v):
    """Euclidean norm over the last axis, summed left to right as scipy's Cython does."""
    total = v[..., 0] * v[..., 0]
    for k in range(1, v.shape[-1]):
        total = total + v[..., k] * v[..., k]
    return np.sqrt(total)


def _normalised(q):
    norm = _norm(q)
    if np.any(norm == 0):
        raise ValueError("Found zero norm quaternions in `quat`.")
    return q / norm[..., None]


class Rotation:
    """One rotation or a stack of them (quaternions (x, y, z, w), unit length)."""

    def __init__(self, quat, single):
        self._quat, self.single = quat, single

    # -- construction -------------------------------------------------------------------
    @classmethod
    def from_quat(cls, quat):
        q = np.array(quat, dtype=float)
        single = q.ndim == 1
        return cls(_normalised(np.atleast_2d(q)), single)

    @classmethod
    def random(cls, num, rng):
        """``num`` rotations uniform in SO(3): normalised 4-D normal draws from the numpy
        Generator ``rng``, the same draws and quaternions as scipy's ``Rotation.random``."""
        return cls(_normalised(rng.normal(size=(num, 4))), False)

    @classmethod
    def from_matrix(cls, matrix, *, assume_valid=False):
        """Rotation matrices (3, 3) or (N, 3, 3); a matrix not orthogonal to 1e-12 is
        replaced by its nearest rotation (U V^T of its SVD), as scipy does. ``assume_valid``
        (scipy's too): the caller knows them rotations (orthogonal to rounding, det 1), so
        neither the determinant nor the orthogonality is checked: the same quaternions for
        such matrices, in half the time."""
        m = np.array(matrix, dtype=float)
        single = m.ndim == 2
        m = m.reshape(-1, 3, 3)
        if assume_valid:
            return cls(_quat_of_orthogonal(m), single)
        if np.any(_det3(m) <= 0):
            raise ValueError("Non-positive determinant (left-handed or null coordinate frame) "
                             "in a rotation matrix.")
        gram = m @ np.swapaxes(m, 1, 2)
        off = ~np.all(np.isclose(gram, np.eye(3), atol=1e-12), axis=(1, 2))
        if np.any(off):
            U, _, Vt = np.linalg.svd(m[off])
            m[off] = U @ Vt
        return cls(_quat_of_orthogonal(m), single)

    @classmethod
    def from_rotvec(cls, rotvec):
        """Rotation vectors (3,) or (N, 3), radians."""
        v = np.array(rotvec, dtype=float)
        single = v.ndim == 1
        v = np.atleast_2d(v)
        angle = _norm(v)
        small = angle <= SMALL_ANGLE
        a2 = angle * angle  # (+ small: no 0 / 0 where the series is taken; exact elsewhere)
        scale = np.where(small, 0.5 - a2 / 48 + a2 * a2 / 3840, np.sin(angle / 2) / (angle + small))
        return cls(np.concatenate([v * scale[:, None], np.cos(angle / 2)[:, None]], axis=1), single)

    # -- views ---------------------------------------------------------------------------
    def _out(self, a):
        return a[0] if self.single else a

    def as_quat(self):
        return self._out(self._quat.copy())

    def as_matrix(self):
        x, y, z, w = self._quat.T
        x2, y2, z2, w2 = x * x, y * y, z * z, w * w
        xy, zw, xz, yw, yz, xw = x * y, z * w, x * z, y * w, y * z, x * w
        m = np.stack([x2 - y2 - z2 + w2, 2 * (xy - zw), 2 * (xz + yw),
                      2 * (xy + zw), -x2 + y2 - z2 + w2, 2 * (yz - xw),
                      2 * (xz - yw), 2 * (yz + xw), -x2 - y2 + z2 + w2], axis=-1)
        return self._out(m.reshape(-1, 3, 3))

    def as_rotvec(self):
        q = _canonical(self._quat)
        angle = 2 * np.arctan2(_norm(q[:, :3]), q[:, 3])
        small = angle <= SMALL_ANGLE
        a2 = angle * angle
        scale = np.where(small, 2 + a2 / 12 + 7 * a2 * a2 / 2880, angle / (np.sin(angle / 2) + small))
        return self._out(scale[:, None] * q[:, :3])

    def magnitude(self):
        """Rotation angles in [0, pi] (radians)."""
        return self._out(2 * np.arctan2(_norm(self._quat[:, :3]), np.abs(self._quat[:, 3])))

    # -- algebra -------------------------------------------------------------------------
    def inv(self):
        q = self._quat.copy()
        q[:, :3] *= -1
        return Rotation(q, self.single)

    def __mul__(self, other):
        """``self * other``: ``other`` first, then ``self`` (matrices R_self @ R_other);
        one rotation composes with each of a stack."""
        if not isinstance(other, Rotation):
            return NotImplemented
        p, q = np.broadcast_arrays(self._quat, other._quat)
        px, py, pz, pw = p.T
        qx, qy, qz, qw = q.T
        # the vector part's p x q written out: np.cross's products and differences (the
        # same numbers), without its axis moves and copies (two thirds of a 2-row product)
        r = np.stack([pw * qx + qw * px + (py * qz - pz * qy),
                      pw * qy + qw * py + (pz * qx - px * qz),
                      pw * qz + qw * pz + (px * qy - py * qx),
                      pw * qw - px * qx - py * qy - pz * qz], axis=-1)
        return Rotation(_normalised(r), self.single and other.single)

    def __len__(self):
        if self.single:
            raise TypeError("Single rotation has no len().")
        return len(self._quat)

    def __getitem__(self, index):
        if self.single:
            raise TypeError("Single rotation is not subscriptable.")
        q = self._quat[index]
        return Rotation(np.atleast_2d(q), q.ndim == 1)


def _det3(m):
    """det of 3 x 3 matrices (N, 3, 3) by cofactors along the first row (a twentieth of
    LAPACK's batched cost at N = 6000; its sign is all ``from_matrix`` reads)."""
    return (m[:, 0, 0] * (m[:, 1, 1] * m[:, 2, 2] - m[:, 1, 2] * m[:, 2, 1])
            - m[:, 0, 1] * (m[:, 1, 0] * m[:, 2, 2] - m[:, 1, 2] * m[:, 2, 0])
            + m[:, 0, 2] * (m[:, 1, 0] * m[:, 2, 1] - m[:, 1, 1] * m[:, 2, 0]))


def _quat_of_orthogonal(m):
    """Quaternions of orthogonal matrices (N, 3, 3): scipy's choice among the largest of
    the diagonal and the trace, then normalised."""
    trace = m[:, 0, 0] + m[:, 1, 1] + m[:, 2, 2]
    choice = np.argmax(np.stack([m[:, 0, 0], m[:, 1, 1], m[:, 2, 2], trace], axis=1), axis=1)
    q = np.empty((len(m), 4))
    for i in range(3):
        j, k = (i + 1) % 3, (i + 2) % 3
        s = choice == i
        q[s, i] = 1 - trace[s] + 2 * m[s, i, i]
        q[s, j] = m[s, j, i] + m[s, i, j]
        q[s, k] = m[s, k, i] + m[s, i, k]
        q[s, 3] = m[s, k, j] - m[s, j, k]
    s = choice == 3
    q[s, 0] = m[s, 2, 1] - m[s, 1, 2]
    q[s, 1] = m[s, 0, 2] - m[s, 2, 0]
    q[s, 2] = m[s, 1, 0] - m[s, 0, 1]
    q[s, 3] = 1 + trace[s]
    return _normalised(q)


def _canonical(q):
    """q or -q, whichever has w > 0 (ties broken by x, y, z in turn), as scipy's."""
    w0 = q[:, 3] == 0
    flip = (q[:, 3] < 0) | (w0 & (q[:, 0] < 0))
    wx0 = w0 & (q[:, 0] == 0)
    flip |= wx0 & (q[:, 1] < 0)
    flip |= wx0 & (q[:, 1] == 0) & (q[:, 2] < 0)
    return np.where(flip[:, None], -q, q)


class Slerp:
    """Spherical linear interpolation of rotations (N >= 2) at increasing ``times`` (s),
    constant angular velocity between neighbours, as scipy's Slerp."""

    def __init__(self, times, rotations):
        self.times = np.asarray(times, dtype=float)
        self.timedelta = np.diff(self.times)
        if np.any(self.timedelta <= 0):
            raise ValueError("Times must be in strictly increasing order.")
        self.rotations = rotations[:-1]
        self.rotvecs = (self.rotations.inv() * rotations[1:]).as_rotvec()

    def __call__(self, times):
        t = np.asarray(times, dtype=float)
        single = t.ndim == 0
        t = np.atleast_1d(t)
        ind = np.searchsorted(self.times, t) - 1
        ind[t == self.times[0]] = 0
        if np.any((ind < 0) | (ind > len(self.rotations) - 1)):
            raise ValueError(f"Interpolation times must be within the range [{self.times[0]}, "
                             f"{self.times[-1]}], both inclusive.")
        alpha = (t - self.times[ind]) / self.timedelta[ind]
        out = self.rotations[ind] * Rotation.from_rotvec(self.rotvecs[ind] * alpha[:, None])
        return out[0] if single else out
