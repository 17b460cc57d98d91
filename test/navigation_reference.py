"""The numpy reference of the navigation manifold's compiled kernel (manifold/kernels.py),
never used by the package: F (84,) and F_X (84, 90) of ``NavigationManifold`` written with
numpy arrays, which test_manifold_kernel.py compares the kernel with (to 1e-12) and
benchmarks/manifold_kernel.py --reference times in the kernel's place; the scalar rotation
and its derivatives the reference uses (test_manifold.py checks them against
model.pose)."""

import math
from types import SimpleNamespace

import numpy as np

from cdh_planner.manifold.layout import I_D, I_F, I_G, I_L, I_P, I_S, I_T, I_TAU, I_V, N_EQS, N_VARS
from cdh_planner.wrench import skew


def residual_and_jacobian_reference(nav, X, jacobian=True):
    """F(X) (84,) and F_X(X) (84, 90) in physical units of the NavigationManifold ``nav``:
    the numpy reference of its compiled kernel (a method in all but name: the benchmark
    puts it in the class's place)."""
    tb = _tables(nav)
    p, tau, d, l, f0, G, g, s, t = _unpack(X)
    R, dR = rotation_and_derivatives(tau)
    c = p + R @ nav.g_load
    w0, P = nav._wrench_and_factor(c)
    cols = np.concatenate([d, np.einsum("kij,kj->ki", tb.a_skew, d)], axis=1)  # row i = l_i J col i
    J = (cols / l[:, None]).T
    JG = J @ G
    M = P @ J
    vdiag = np.linalg.norm(G, axis=1)
    mu_l, mu_lo, mu_hi = nav.margins(l, f0, vdiag)

    Fv = np.empty(N_EQS)
    Fv[0:18] = (d - (p + nav.b @ R.T - nav.a)).ravel()
    Fv[18:24] = l ** 2 - np.einsum("ij,ij->i", d, d)
    Fv[24:30] = J @ f0 - w0
    Fv[30:66] = (P @ JG - np.eye(6)).ravel()
    Fv[66:72] = mu_l - np.exp(g / nav.kappa)
    Fv[72:78] = mu_lo - np.exp(s / nav.kappa)
    Fv[78:84] = mu_hi - np.exp(t / nav.kappa)
    if not jacobian:
        return Fv, None

    Jx = tb.template.copy()  # the constant entries (identities of Eq. 1)
    db = np.einsum("ijk,nj->nik", dR, nav.b)  # (6 cables, 3, 3 angles)
    dc_dtau = np.einsum("ijk,j->ik", dR, nav.g_load)  # (3, 3)
    rows = tb.rows6
    # (1)
    Jx[0:18, I_TAU:I_D] = -db.reshape(18, 3)
    # (2)
    Jx[18 + rows, I_L + rows] = 2.0 * l
    Jx[tb.r2, tb.c2] = -2.0 * d.ravel()
    # dJcol_i / dd_i = [I; [a_i]x] / l_i and dJcol_i / dl_i = -Jcol_i / l_i
    dcol_dd = tb.col_dd / l[:, None, None]  # (6, 6, 3)
    dcol_dl = -J.T / l[:, None]  # (6, 6): row i = d Jcol_i / d l_i
    # (4) J f0 - w0
    Jx[24:30, I_F:I_V] = J
    Jx[24:30, I_D:I_L] = (f0[:, None, None] * dcol_dd).transpose(1, 0, 2).reshape(6, 18)
    Jx[24:30, I_L:I_F] = (f0[:, None] * dcol_dl).T
    if nav.load_frame:
        Fx = tb.force_skew  # d(-w0)/dc = [0; [F]x]
        Jx[27:30, I_P:I_TAU] = Fx
        Jx[27:30, I_TAU:I_D] = Fx @ dc_dtau
    # envelope: P J G - I, rows (k, j) row-major
    blk = Jx[30:66]
    blk[tb.r_env, tb.c_env] = M[tb.k_env]
    # d(P J G)_kj / dJcol_i = P_k: G_ij
    D = np.einsum("ka,ij->ikja", P, G).reshape(6, 36, 6)
    blk[:, I_D:I_L] = np.einsum("ira,iac->ric", D, dcol_dd).reshape(36, 18)
    blk[:, I_L:I_F] = np.einsum("ira,ia->ri", D, dcol_dl)
    if nav.load_frame:
        dc = np.einsum("kb,mbc,cj->kjm", nav.L3T, tb.de_dc, JG).reshape(36, 3)
        blk[:, I_P:I_TAU] = dc
        blk[:, I_TAU:I_D] = dc @ dc_dtau
    # (10)-(12)
    rr = nav.robot
    dv = (G / vdiag[:, None] / nav.range_f[:, None]).ravel()  # d|G_i| / dG_i over the range
    Jx[66 + rows, I_L + rows] = (rr.length_max + rr.length_min - 2.0 * l) / nav.half_range_l ** 2
    Jx[66 + rows, I_G + rows] = -np.exp(g / nav.kappa) / nav.kappa
    Jx[72 + rows, I_F + rows] = 1.0 / nav.range_f
    Jx[78 + rows, I_F + rows] = -1.0 / nav.range_f
    Jx[72 + tb.r_v, I_V + tb.c_v] = -dv
    Jx[78 + tb.r_v, I_V + tb.c_v] = -dv
    Jx[72 + rows, I_S + rows] = -np.exp(s / nav.kappa) / nav.kappa
    Jx[78 + rows, I_T + rows] = -np.exp(t / nav.kappa) / nav.kappa
    return Fv, Jx


def _tables(nav):
    """Constant entries and scatter indices of F_X for ``nav`` (computed once per manifold)."""
    cached = getattr(nav, "_reference_tables", None)
    if cached is not None:
        return cached
    tb = SimpleNamespace()
    tb.a_skew = skew(nav.a)  # (6, 3, 3)
    tb.de_dc = np.zeros((3, 6, 6))  # d e(c) / dc_m
    for m in range(3):
        tb.de_dc[m, 3:, :3] = -skew(np.eye(3)[m])
    tb.rows6 = np.arange(6)
    tb.template = np.zeros((N_EQS, N_VARS))
    for i in range(6):
        r0 = 3 * i
        tb.template[r0:r0 + 3, I_P:I_TAU] = -np.eye(3)
        tb.template[r0:r0 + 3, I_D + r0:I_D + r0 + 3] = np.eye(3)
    tb.r2 = 18 + np.repeat(tb.rows6, 3)
    tb.c2 = I_D + np.arange(18)
    tb.col_dd = np.concatenate([np.broadcast_to(np.eye(3), (6, 3, 3)), tb.a_skew], axis=1)
    idx_k, idx_j = np.repeat(tb.rows6, 6), np.tile(tb.rows6, 6)
    tb.r_env = np.arange(36)[:, None]
    tb.c_env = I_V + 6 * tb.rows6[None, :] + idx_j[:, None]
    tb.k_env = idx_k
    tb.r_v = np.repeat(tb.rows6, 6)
    tb.c_v = np.arange(36)
    tb.force_skew = skew(nav.w_local[:3])
    nav._reference_tables = tb
    return tb


def _unpack(X):
    p, tau = X[I_P:I_TAU], X[I_TAU:I_D]
    d = X[I_D:I_L].reshape(6, 3)
    l, f0 = X[I_L:I_F], X[I_F:I_V]
    G = X[I_V:I_G].reshape(6, 6)  # tension envelope map: f = f0 + G z, |z| <= 1
    return p, tau, d, l, f0, G, X[I_G:I_S], X[I_S:I_T], X[I_T:N_VARS]


def rotation_and_derivatives(tau):
    """R = Rz(phi) Ry(theta) Rz(sigma - phi) of one pose and dR / d(phi, theta, sigma)
    stacked as (3, 3, 3) (last index = angle); scalar code, as the kernel computes it."""
    phi, theta, sigma = float(tau[0]), float(tau[1]), float(tau[2])
    cf, sf = math.cos(phi), math.sin(phi)
    ct, st = math.cos(theta), math.sin(theta)
    cp, sp = math.cos(sigma - phi), math.sin(sigma - phi)
    Rzf = np.array([[cf, -sf, 0.0], [sf, cf, 0.0], [0.0, 0.0, 1.0]])
    dRzf = np.array([[-sf, -cf, 0.0], [cf, -sf, 0.0], [0.0, 0.0, 0.0]])
    Ry = np.array([[ct, 0.0, st], [0.0, 1.0, 0.0], [-st, 0.0, ct]])
    dRy = np.array([[-st, 0.0, ct], [0.0, 0.0, 0.0], [-ct, 0.0, -st]])
    Rzp = np.array([[cp, -sp, 0.0], [sp, cp, 0.0], [0.0, 0.0, 1.0]])
    dRzp = np.array([[-sp, -cp, 0.0], [cp, -sp, 0.0], [0.0, 0.0, 0.0]])
    A = Rzf @ Ry
    d_sigma = A @ dRzp
    dR = np.empty((3, 3, 3))
    dR[:, :, 0] = dRzf @ Ry @ Rzp - d_sigma
    dR[:, :, 1] = Rzf @ dRy @ Rzp
    dR[:, :, 2] = d_sigma
    return A @ Rzp, dR
