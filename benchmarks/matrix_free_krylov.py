"""Issue 34: Krylov policy evaluation inside the matrix-free solve, measured against the shipped
modified policy iteration (one thread, so every count is deterministic). Not kept: the numbers are
in benchmarks/README.md's matrix-free section and docs/matrix-free.md.

    python benchmarks/matrix_free_krylov.py                        # processes 1-4 caps 8-14, the mix cap 6
    python benchmarks/matrix_free_krylov.py --instances paper_p1234:12 --starts 1e-3:1e-2,1e-5:1e-4

Per instance, in one process, one thread:

* ``default`` -- :func:`matrix_free_value_iteration` with its defaults: passes (improvement sweeps
  and certificates + evaluation sweeps) and CPU seconds.
* ``krylov eps:kappa`` -- the same solver to a relative bracket of ``eps``; then policy iteration
  whose evaluations are BiCGSTAB solves: for the greedy policy pi of the last certificate, the
  average-cost equations (I - P_pi) h + g 1 = c_pi with h(s0) = 0, a nonsingular system in
  (h without s0, g) for a unichain policy, bordered so that one vector holds both (slot s0 holds
  g); the product P_pi v is one matrix-free pass of the fixed policy into a second vector (a
  Jacobi pass: the kernel's ``Write.OUT`` with relaxation 1 and no shift, on the cost-free
  operator). BiCGSTAB starts from the certificate's h and the bracket's midpoint and stops when
  its residual (T_pi h - h - g, whose span is the fixed-policy bracket) is within
  ``kappa`` x the last bracket's width (or a quarter of the target width); then one certificate
  pass over every action (the solver's bracket, unchanged) and its greedy policy, until the
  bracket closes at 1e-9. Passes = the first phase's + BiCGSTAB's products + certificates; the
  vector work outside the passes is counted in *streams* (one vector read or written: 8 bytes a
  state; a pass moves ~17 bytes a state).
* ``--from-zero``: BiCGSTAB on the optimal policy's evaluation from h = 0 against
  :func:`matrix_free_evaluate` (its relaxed Gauss-Seidel sweeps), products and sweeps to 1e-9
  (``--gmres 20,50``: scipy's GMRES(m) too, to a relative residual of 1e-10; m + 1 vectors), and
  BiCGSTAB left-preconditioned by one Gauss-Seidel sweep (:class:`SweepBordered`).
"""
from __future__ import annotations

import argparse
import os
import sys
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(ROOT))

import wncs_lp  # noqa: E402
from wncs_lp.models.system import System  # noqa: E402
from wncs_lp.solvers.matrix_free import BoxLayout, matrix_free_evaluate, matrix_free_value_iteration  # noqa: E402
from wncs_lp.solvers.matrix_free.operator import Operator, Reduce, Write, with_cost  # noqa: E402
from wncs_lp.solvers.matrix_free.sweeper import Sweeper  # noqa: E402

TOL = 1e-9


class Bordered:
    """The bordered evaluation system of one fixed policy, its products counted."""

    def __init__(self, system: System, pol: np.ndarray):
        layout = BoxLayout.from_system(system, "hull")
        op = Operator.build(system, layout)
        self.n, self.pol = layout.n_states, pol
        self.sw = Sweeper(op, 1, None)
        self.sw0 = Sweeper(with_cost(op, np.zeros((op.N, int(op.caps.max())))), 1, None)
        self.products = self.streams = 0

    def cost(self) -> np.ndarray:
        c = np.empty(self.n)
        self.sw.fixed(np.zeros(self.n), c, self.pol, Write.OUT, 1.0, 0.0)
        self.products += 1
        self.streams += 1
        return c

    def mul(self, x: np.ndarray, out: np.ndarray) -> None:
        """out = (I - P_pi) v + g 1, v = x with v[0] = 0, g = x[0]."""
        g = x[0]
        x[0] = 0.0
        self.sw0.fixed(x, out, self.pol, Write.OUT, 1.0, 0.0)  # P_pi v
        np.subtract(x, out, out)
        out += g
        x[0] = g
        self.products += 1
        self.streams += 5

    def bicgstab(self, x: np.ndarray, f: np.ndarray, target: float, max_it: int = 2000) -> int:
        """BiCGSTAB on B x = f from x (in place) until max |residual| <= target; iterations."""
        n, S = self.n, 0
        r = np.empty(n)
        self.mul(x, r)
        np.subtract(f, r, r)
        rhat = r.copy()
        p, v, t = np.zeros(n), np.zeros(n), np.empty(n)
        rho = alpha = om = 1.0
        S += 5
        for k in range(1, max_it + 1):
            rho1 = float(rhat @ r)
            beta = (rho1 / rho) * (alpha / om)
            p -= om * v
            p *= beta
            p += r
            self.mul(p, v)
            alpha = rho1 / float(rhat @ v)
            r -= alpha * v
            x += alpha * p
            S += 2 + 8 + 2 + 3 + 3
            if np.abs(r).max() <= target:
                self.streams += S + 1
                return k
            self.mul(r, t)
            om = float(t @ r) / float(t @ t)
            x += om * r
            r -= om * t
            rho = rho1
            S += 4 + 3 + 3 + 2
            if np.abs(r).max() <= target:
                break
        self.streams += S
        return k


class SweepBordered(Bordered):
    """The same system left-preconditioned by one relaxed Gauss-Seidel sweep M (relaxation
    ``omega``): M^-1 (I - P_pi) v = v - G v, G the sweep's iteration matrix (an in-place sweep of
    the cost-free operator on a copy of v), the border column M^-1 1 (a sweep of the unit cost
    from 0) and the right side M^-1 c_pi (a sweep of the cost from 0). One thread only: with two,
    the in-place sweep is asynchronous, not a fixed linear operator."""

    def __init__(self, system: System, pol: np.ndarray, omega: float = 1.0):
        super().__init__(system, pol)
        op = self.sw.op
        unit = np.zeros((op.N, int(op.caps.max())))
        unit[0, :] = 1.0
        self.omega = omega
        self.w = np.zeros(self.n)
        Sweeper(with_cost(op, unit), 1, None).fixed(self.w, None, pol, Write.IN_PLACE, omega, 0.0)
        self.products += 1

    def cost(self) -> np.ndarray:
        f = np.zeros(self.n)
        self.sw.fixed(f, None, self.pol, Write.IN_PLACE, self.omega, 0.0)
        self.products += 1
        return f

    def mul(self, x: np.ndarray, out: np.ndarray) -> None:
        g = x[0]
        x[0] = 0.0
        np.copyto(out, x)
        self.sw0.fixed(out, None, self.pol, Write.IN_PLACE, self.omega, 0.0)  # G v
        np.subtract(x, out, out)
        out += g * self.w
        x[0] = g
        self.products += 1
        self.streams += 8


def krylov_solve(system: System, eps: float, kappa: float) -> dict:
    """The first phase to ``eps``, then policy iteration with BiCGSTAB evaluations (module doc)."""
    c0 = time.process_time()
    s1 = matrix_free_value_iteration(system, threads=1, tol=eps)
    h = s1.bias.copy()
    lo, hi = s1.gain_lower, s1.gain_upper
    B = Bordered(system, s1.local_actions.copy())
    first, certs, log = s1.stats["sweeps"] + s1.stats["eval_sweeps"], 0, []
    while True:
        mid, width = 0.5 * (lo + hi), hi - lo
        h -= h[0]
        h[0] = mid
        its = B.bicgstab(h, B.cost(), max(kappa * width, 0.25 * TOL * abs(mid)))
        h[0] = 0.0
        lo, hi = B.sw.all_actions(h, None, B.pol, None, Reduce.MIN, Write.NONE, True, 1.0, 0.0)
        certs += 1
        log.append(f"{its} its -> {(hi - lo) / abs(0.5 * (lo + hi)):.1e}")
        if hi - lo <= TOL * abs(0.5 * (lo + hi)) or certs >= 40:
            break
    return dict(passes=first + B.products + certs, first=first, products=B.products, certs=certs,
                streams=B.streams, cpu=time.process_time() - c0, lo=lo, hi=hi, log=log)


def from_zero(system: System, opt, restarts: list[int]) -> str:
    """The optimal policy's evaluation from h = 0: Gauss-Seidel sweeps, BiCGSTAB, GMRES(m)."""
    import scipy.sparse.linalg as sla

    c0 = time.process_time()
    ev = matrix_free_evaluate(system, opt, threads=1)
    parts = [f"Gauss-Seidel evaluation {ev.iterations} sweeps ({time.process_time() - c0:.2f} s CPU)"]
    B = Bordered(system, opt.local_actions.copy())
    x = np.zeros(B.n)
    c0 = time.process_time()
    B.bicgstab(x, B.cost(), 0.25 * TOL * abs(opt.gain))
    x[0] = 0.0
    lo, hi = B.sw.fixed(x, None, B.pol, Write.NONE, 1.0, 0.0)
    parts.append(f"BiCGSTAB {B.products} products ({time.process_time() - c0:.2f} s CPU), "
                 f"width {(hi - lo) / abs(lo):.1e}")
    # preconditioned by a sweep: its residual is M^-1 (T_pi h - h - g); stopped at the same target
    S = SweepBordered(system, opt.local_actions.copy())
    x = np.zeros(S.n)
    S.bicgstab(x, S.cost(), 0.25 * TOL * abs(opt.gain))
    x[0] = 0.0
    lo, hi = S.sw.fixed(x, None, S.pol, Write.NONE, 1.0, 0.0)
    parts.append(f"BiCGSTAB preconditioned by a Gauss-Seidel sweep {S.products} products, "
                 f"width {(hi - lo) / abs(lo):.1e}")
    for m in restarts:
        B.products = 0
        out = np.empty(B.n)
        A = sla.LinearOperator((B.n, B.n), dtype=float, matvec=lambda v: (B.mul(np.array(v, dtype=float), out),
                                                                          out.copy())[1])
        f = B.cost()
        x, _ = sla.gmres(A, f, rtol=0.1 * TOL, restart=m, maxiter=100)  # relative 2-norm of the residual
        x[0] = 0.0
        lo, hi = B.sw.fixed(x, None, B.pol, Write.NONE, 1.0, 0.0)
        parts.append(f"GMRES({m}) {B.products} products, width {(hi - lo) / abs(lo):.1e}")
    return "optimal policy from h = 0: " + "; ".join(parts)


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--instances", default="paper_p1234:8,paper_p1234:12,paper_p1234:14,bounds_mix6:6")
    ap.add_argument("--starts", default="1e-3:1e-2,1e-5:1e-4", help="eps:kappa pairs (module doc)")
    ap.add_argument("--from-zero", action="store_true")
    ap.add_argument("--gmres", default="", help="with --from-zero: GMRES restart lengths too, e.g. 20,50")
    a = ap.parse_args(argv)
    print(f"Krylov evaluation, one thread; load {os.getloadavg()[0]:.2f}", flush=True)
    for item in a.instances.split(","):
        name, cap = item.split(":")
        system = System.from_scenario(wncs_lp.load_scenario(wncs_lp.scenario_path(name), [f"tau_cap={cap}"]))
        c0 = time.process_time()
        ref = matrix_free_value_iteration(system, threads=1)
        cpu_ref = time.process_time() - c0
        sw, ev = ref.stats["sweeps"], ref.stats["eval_sweeps"]
        print(f"{name} cap {cap}: default {sw + ev} passes ({sw} + {ev}), {cpu_ref:.2f} s CPU, "
              f"g* {ref.gain:.10f}", flush=True)
        for pair in a.starts.split(","):
            eps, kappa = (float(v) for v in pair.split(":"))
            r = krylov_solve(system, eps, kappa)
            inside = ref.gain_lower <= 0.5 * (r["lo"] + r["hi"]) <= ref.gain_upper
            print(f"  krylov {eps:g}:{kappa:g}: {r['passes']} passes ({r['first']} + {r['products']} products + "
                  f"{r['certs']} certificates), {r['streams'] / r['products']:.1f} vector streams a product, "
                  f"{r['cpu']:.2f} s CPU ({r['cpu'] / cpu_ref:.2f}x), passes {r['passes'] / (sw + ev):.2f}x; "
                  f"g in the default's bracket: {inside}; {', '.join(r['log'])}", flush=True)
        if a.from_zero:
            print("  " + from_zero(system, ref, [int(m) for m in a.gmres.split(",") if m]), flush=True)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
