r"""Relaxation 2's LP over per-process occupation measures, and a first-order method for it.

The dual of the approximate LP of relaxation 2 (see :mod:`wncs_lp.bounds.joint`) is

.. math::

    \min \sum_k \langle q_k, y_k\rangle \quad\text{s.t.}\quad
    \sum_{p \ni C} y_k(\tau, p) = \sum_{(\tau_0, p_0, o) \to (\tau, C)} P(o|p_0)\, y_k(\tau_0, p_0)
    \;\;(k, \tau, C), \qquad
    \sum_\tau y_k(\tau, p) = x(p) \;\;(k, p), \qquad \sum_p x(p) = 1, \qquad y, x \ge 0,

one occupation measure y_k(tau, p) per process on its chain (tau_k, C), all with the same
(C, a) marginal x. Its row duals are the tables h_k(tau, C) (balance rows), -u_k(p) (coupling
rows) and g (the normalisation): exactly the approximate LP's variables.

:class:`JointLP` is this LP in the form min c^T z s.t. A z = b, z >= 0, applied without storing
A (numba kernels; a scipy CSR matrix without numba), equilibrated by a few rounds of 1-norm
row / column scaling. Some balance rows are *dropped* (their dual fixed at 0): process k's rows
(tau = 1, C) for k >= 1 and process 0's row (tau = 1, C_0). This loses nothing: moving f(C)
between two processes' tables changes no constraint of the approximate LP (see
:func:`pin_tables`), so the duals can always be taken zero there; it removes the LP's flat dual
directions.

:class:`HalpernPDHG` runs the restarted Halpern primal-dual hybrid gradient with reflection
(Lu and Yang, "Restarted Halpern PDHG for linear programming", 2024): two operator
applications and a few vector passes an iteration. It reaches a good approximate dual quickly
but is never trusted -- its duals only propose prices, which :mod:`wncs_lp.bounds.joint`
certifies through the priced per-process chains.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import scipy.sparse as sp

from .joint_chains import JointData, Kernels

__all__ = ["JointLP", "HalpernPDHG", "lp_shape", "pin_tables"]


def lp_shape(caps: np.ndarray, n_configs: int, n_pairs: int, n_outcomes: int) -> dict:
    """Rows, columns and (unmerged) nonzeros of the LP for these sizes, without building anything."""
    caps = np.asarray(caps, dtype=np.int64)
    n = int(caps.size)
    tau_cols = int(caps.sum())
    return {
        "rows": tau_cols * n_configs + n * n_pairs + 1,
        "cols": tau_cols * n_pairs + n_pairs,
        "nnz": 2 * tau_cols * n_pairs + tau_cols * n_outcomes + (n + 1) * n_pairs,
    }


def pin_tables(tables) -> list[np.ndarray]:
    """Equivalent tables with h_k(1, C) = 0 for every k >= 1 and C, and h_0(1, C_0) = 0.

    Moving f(C) from one process's table to another's, h_j(., C) += f(C), h_k(., C) -= f(C),
    changes no constraint of the approximate LP: u_j and u_k move by f(C) - E f(C') and
    -(f(C) - E f(C')), which cancel in the sum over processes. So do per-process constants.
    """
    out = [np.array(h, dtype=float, copy=True) for h in tables]
    for k in range(1, len(out)):
        f = out[k][:, 0].copy()
        out[k] -= f[:, None]
        out[0] += f[:, None]
    out[0] -= out[0][0, 0]
    return out


def _offsets(data: JointData) -> tuple[np.ndarray, np.ndarray, int, int, int]:
    """(y_off, b_off, c_off, n_rows, n_cols): where process k's occupation columns and balance rows
    start, where the coupling rows start, and the LP's size (the last row: the normalisation)."""
    N, nC, P, caps = data.n_processes, data.n_configs, data.n_pairs, data.caps
    y_off = np.r_[0, np.cumsum(caps * P)].astype(np.int64)
    b_off = np.r_[0, np.cumsum(caps * nC)].astype(np.int64)
    c_off = int(b_off[-1])
    return y_off, b_off, c_off, c_off + N * P + 1, int(y_off[-1]) + P


def _kept_rows(data: JointData) -> np.ndarray:
    """The rows kept (bool): all but process 0's row (tau = 1, C_0) and the rows (tau = 1, C) of
    every other process (see the module docstring: their duals can be taken 0)."""
    _, b_off, _, n_rows, _ = _offsets(data)
    keep = np.ones(n_rows, dtype=bool)
    keep[0] = False
    for k in range(1, data.n_processes):
        keep[b_off[k]:b_off[k + 1]:data.caps[k]] = False
    return keep


@dataclass(frozen=True, eq=False)
class JointLP:
    """The equilibrated LP: B = diag(row_scale) A diag(col_scale), applied by :meth:`matvec`.

    Columns: y_k(p, t) at ``y_off[k] + p * cap_k + t``, then x(p) at ``x_off + p``.
    Rows: process k's balance row of state (c, t) at ``b_off[k] + c * cap_k + t``; coupling (k, p)
    at ``c_off + k P + p``; the normalisation last. ``free`` is 0 on the dropped rows.
    ``b`` and ``c`` are unscaled; the scaled problem's are ``row_scale * b``, ``col_scale * c``.
    """

    data: JointData
    kern: Kernels
    y_off: np.ndarray
    x_off: int
    b_off: np.ndarray
    c_off: int
    free: np.ndarray
    b: np.ndarray
    c: np.ndarray
    row_scale: np.ndarray
    col_scale: np.ndarray
    csr: sp.csr_matrix | None

    @property
    def shape(self) -> tuple[int, int]:
        return int(self.free.size), int(self.c.size)

    @classmethod
    def build(cls, data: JointData, kern: Kernels, scaling_rounds: int = 8) -> "JointLP":
        N, nC, P = data.n_processes, data.n_configs, data.n_pairs
        caps = data.caps
        y_off, b_off, c_off, n_rows, n_cols = _offsets(data)
        free = _kept_rows(data).astype(float)
        c = np.zeros(n_cols)
        for k in range(N):
            c[y_off[k]:y_off[k + 1]] = np.tile(data.q[k], P)
        b = np.zeros(n_rows)
        b[-1] = 1.0
        csr = None if kern.mod is not None else _assemble(data, y_off, b_off, c_off, n_rows, n_cols)
        lp = cls(data, kern, y_off, int(y_off[-1]), b_off, c_off, free, b, c, np.ones(n_rows), np.ones(n_cols), csr)
        lp._equilibrate(scaling_rounds)
        return lp

    # ------------------------------------------------------------------ the operator (scaled)
    def _args(self):
        d = self.data
        return (d.pair_c, d.out_ptr, d.out_nxt, d.out_prob, d.sat, d.caps, self.y_off, self.b_off, self.c_off,
                self.x_off)

    def matvec(self, z: np.ndarray, out: np.ndarray, absval: bool = False) -> np.ndarray:
        """out = B z (|B| z with ``absval``)."""
        mod = self.kern.mod
        if mod is None:
            A = abs(self.csr) if absval else self.csr
            out[:] = self.row_scale * (A @ (self.col_scale * z))
        else:
            self.kern.parallel(mod.lp_matvec_ser, mod.lp_matvec_par, z, self.row_scale, self.col_scale, out,
                               1.0 if absval else -1.0, *self._args())
        return out

    def rmatvec(self, lam: np.ndarray, out: np.ndarray, absval: bool = False) -> np.ndarray:
        """out = B^T lam (|B|^T lam with ``absval``)."""
        mod = self.kern.mod
        if mod is None:
            A = abs(self.csr) if absval else self.csr
            out[:] = self.col_scale * (A.T @ (self.row_scale * lam))
        else:
            self.kern.parallel(mod.lp_rmatvec_ser, mod.lp_rmatvec_par, lam, self.row_scale, self.col_scale, out,
                               1.0 if absval else -1.0, *self._args())
        return out

    def _equilibrate(self, rounds: int) -> None:
        """Rounds of 1-norm equilibration on the free rows: row_scale /= sqrt(row abs-sum),
        col_scale /= sqrt(column abs-sum) (the last round is Pock-Chambolle's alpha = 1 scaling)."""
        n_rows, n_cols = self.shape
        rs, cs = np.empty(n_rows), np.empty(n_cols)
        for _ in range(rounds):
            self.matvec(np.ones(n_cols), rs, absval=True)
            self.rmatvec(self.free, cs, absval=True)
            self.row_scale[:] = np.where(self.free > 0, self.row_scale / np.sqrt(np.maximum(rs, 1e-300)), 1.0)
            self.col_scale[:] /= np.sqrt(np.maximum(cs, 1e-300))

    # ------------------------------------------------------------------ conversions (unscaled)
    def tables(self, lam: np.ndarray) -> list[np.ndarray]:
        """The balance duals h_k(tau, C) of an (unscaled) dual vector, as (|C|, tau_hat_k) tables."""
        d = self.data
        return [lam[self.b_off[k]:self.b_off[k + 1]].reshape(d.n_configs, -1).copy() for k in range(d.n_processes)]

    def occupations(self, z: np.ndarray) -> list[np.ndarray]:
        """The (unscaled) primal's y_k as (|C x A|, tau_hat_k) arrays."""
        P = self.data.n_pairs
        return [z[self.y_off[k]:self.y_off[k + 1]].reshape(P, -1) for k in range(self.data.n_processes)]

    def primal_from(self, occupations, x: np.ndarray) -> np.ndarray:
        """The (unscaled) primal vector of per-process occupations (|C x A|, tau_hat_k) and marginal x."""
        return np.concatenate([np.asarray(y, float).ravel() for y in occupations] + [np.asarray(x, float)])

    def dual_from(self, pinned_tables, u: np.ndarray, g: float) -> np.ndarray:
        """The (unscaled) dual vector of pinned tables (:func:`pin_tables`), u_k(p) and g."""
        lam = np.concatenate([np.asarray(h, float).ravel() for h in pinned_tables] + [-np.asarray(u).ravel(), [g]])
        return lam * self.free


def _assemble(data: JointData, y_off, b_off, c_off, n_rows, n_cols) -> sp.csr_matrix:
    """The unscaled A as a scipy CSR matrix (the numpy path's operator; the interior point's matrix
    is :func:`~wncs_lp.bounds.joint_symmetry.symmetric_lp`, equal to it without symmetry)."""
    N, P = data.n_processes, data.n_pairs
    rows, cols, vals = [], [], []
    lens = np.diff(data.out_ptr)
    for k in range(N):
        cap = int(data.caps[k])
        p = np.repeat(np.arange(P), cap)
        t = np.tile(np.arange(cap), P)
        col = y_off[k] + p * cap + t
        rows += [b_off[k] + data.pair_c[p] * cap + t, c_off + k * P + p]
        cols += [col, col]
        vals += [np.ones(col.size), np.ones(col.size)]
        o = np.repeat(data.out_ptr[p] - (np.cumsum(lens[p]) - lens[p]), lens[p]) + np.arange(int(lens[p].sum()))
        nt = np.minimum(np.repeat(t, lens[p]) + 1, data.sat[o, k])
        rows.append(b_off[k] + data.out_nxt[o] * cap + nt)
        cols.append(np.repeat(col, lens[p]))
        vals.append(-data.out_prob[o])
    xp = np.arange(P)
    for k in range(N):
        rows.append(c_off + k * P + xp)
        cols.append(y_off[-1] + xp)
        vals.append(-np.ones(P))
    rows.append(np.full(P, n_rows - 1))
    cols.append(y_off[-1] + xp)
    vals.append(np.ones(P))
    return sp.csr_matrix((np.concatenate(vals), (np.concatenate(rows), np.concatenate(cols))), shape=(n_rows, n_cols))


class HalpernPDHG:
    """Restarted Halpern PDHG with reflection on a :class:`JointLP`, warm-startable, run in chunks.

    Restarts (to the last PDHG output, which becomes the Halpern anchor) happen when the
    fixed-point residual fell to 0.2 of its value at the last restart, or to 0.8 and started
    rising, or after 0.36 of the iterations so far. The primal weight w (tau = eta / w,
    sigma = eta w) follows PDLP's update at restarts (geometric smoothing of the ratio of the
    dual to the primal movement) but **only downwards**: on this LP, once the occupation
    measures have settled, the duals of states no policy visits keep drifting without changing
    anything, the ratio grows, and a growing w freezes the primal (measured: the certified bound
    stalled at processes 1-4, cap 20, while w climbed from 1e5 to 1e9).
    """

    def __init__(self, lp: JointLP, z0: np.ndarray, lam0: np.ndarray, rho: float = 1.0,
                 rng: np.random.Generator | None = None):
        self.lp, self.rho = lp, float(rho)
        self.kern = lp.kern
        n_rows, n_cols = lp.shape
        self.bs, self.cs = lp.b * lp.row_scale, lp.c * lp.col_scale
        self.z = np.ascontiguousarray(z0 / lp.col_scale)
        self.lam = np.ascontiguousarray(lam0 / lp.row_scale) * lp.free
        self.zt, self.zx, self.aty = np.empty(n_cols), np.empty(n_cols), np.empty(n_cols)
        self.lt, self.az = np.empty(n_rows), np.empty(n_rows)
        self.eta = 0.99 / self._norm_estimate(rng or np.random.default_rng(0))
        nz, nl = np.linalg.norm(self.z), np.linalg.norm(self.lam)
        self.w = nl / nz if nz > 0 and nl > 0 else max(np.linalg.norm(self.cs), 1e-6) / max(np.linalg.norm(self.bs), 1e-6)
        self.w0 = self.w
        self.iterations = 0
        self.restarts = 0
        self._restart_state()

    def _norm_estimate(self, rng: np.random.Generator, iters: int = 30) -> float:
        """||B||_2 by power iteration on B^T B, enlarged 5% for the power method's shortfall."""
        v = rng.standard_normal(self.z.size)
        s = 1.0
        for _ in range(iters):
            v /= np.linalg.norm(v)
            self.lp.matvec(v, self.az)
            self.az *= self.lp.free
            self.lp.rmatvec(self.az, self.aty)
            s = float(np.linalg.norm(self.aty))
            v = self.aty.copy()
        return float(np.sqrt(s)) * 1.05

    # ------------------------------------------------------------------ iteration
    def _restart_state(self) -> None:
        self.zA, self.lA = self.z.copy(), self.lam.copy()
        self.zs, self.ls = self.z.copy(), self.lam.copy()
        self.k = 0
        self.r0 = None
        self.rprev = np.inf

    def _pdhg(self) -> None:
        """(zt, lt) = one PDHG step from (z, lam)."""
        lp, tau, sig = self.lp, self.eta / self.w, self.eta * self.w
        lp.rmatvec(self.lam, self.aty)
        mod = self.kern.mod
        if mod is not None:
            mod.primal_step(self.z, self.cs, self.aty, tau, self.zt, self.zx)
            lp.matvec(self.zx, self.az)
            mod.dual_step(self.lam, self.bs, self.az, sig, lp.free, self.lt)
        else:
            np.maximum(self.z - tau * (self.cs - self.aty), 0.0, out=self.zt)
            np.subtract(2.0 * self.zt, self.z, out=self.zx)
            lp.matvec(self.zx, self.az)
            self.lt[:] = (self.lam + sig * (self.bs - self.az)) * lp.free

    def _halpern(self, x, xt, anchor, a) -> float:
        mod = self.kern.mod
        if mod is not None:
            return mod.halpern_step(x, xt, anchor, a, self.rho)
        r = float(np.dot(xt - x, xt - x))
        x *= -self.rho * a
        x += a * (1.0 + self.rho) * xt + (1.0 - a) * anchor
        return r

    def _restart(self) -> None:
        dz = np.linalg.norm(self.zt - self.zs)
        dl = np.linalg.norm(self.lt - self.ls)
        if dz > 1e-12 and dl > 1e-12:
            w = min(float(np.exp(0.5 * np.log(dl / dz) + 0.5 * np.log(self.w))), self.w)  # only downwards
            self.w = max(w, self.w0 * 1e-9)
        self.z[:] = self.zt
        self.lam[:] = self.lt
        self.restarts += 1
        self._restart_state()

    def run(self, iters: int) -> None:
        """``iters`` more iterations."""
        for _ in range(int(iters)):
            self._pdhg()
            self.iterations += 1
            a = (self.k + 1.0) / (self.k + 2.0)
            rz = self._halpern(self.z, self.zt, self.zA, a)
            rl = self._halpern(self.lam, self.lt, self.lA, a)
            r = float(np.sqrt(self.w * rz + rl / self.w))
            if self.r0 is None:
                self.r0 = r
            elif r <= 0.2 * self.r0 or (r <= 0.8 * self.r0 and r > self.rprev) or self.k >= 0.36 * self.iterations:
                self._restart()
                continue
            self.rprev = r
            self.k += 1

    # ------------------------------------------------------------------ read-out (unscaled)
    @property
    def primal(self) -> np.ndarray:
        """The last PDHG output's primal (unscaled)."""
        return self.zt * self.lp.col_scale

    @property
    def dual(self) -> np.ndarray:
        return self.lt * self.lp.row_scale

    def residuals(self) -> dict:
        """Relative primal / dual infeasibility and duality gap of the last output (two products)."""
        lp = self.lp
        az = lp.matvec(self.zt, np.empty(self.lt.size)) * lp.free
        aty = lp.rmatvec(self.lt, np.empty(self.zt.size))
        pobj, dobj = float(self.cs @ self.zt), float(self.bs @ self.lt)
        return {
            "primal_objective": pobj,
            "dual_objective": dobj,
            "primal_residual": float(np.linalg.norm((az - self.bs * lp.free) / lp.row_scale)) / 2.0,
            "dual_residual": float(np.linalg.norm(np.maximum(aty - self.cs, 0.0) / lp.col_scale))
            / (1.0 + float(np.linalg.norm(lp.c))),
            "gap": abs(pobj - dobj) / (1.0 + abs(pobj) + abs(dobj)),
        }
