#!/usr/bin/python3
"""(a) Ulam's method for the time-tau transfer operator, built with only the
kernels (RK4 + guard event detection, no closed-form flow), M sample points per
cell, N uniform cells per mode.  Measures the invariant density error vs N, M, tau.
Run: python3 ulam1d.py   (use /usr/bin/python3 if python3 is a pyenv shim without numpy)
"""
import os, sys
try:
    import numpy, scipy  # noqa: F401
except ImportError:        # python3 = a pyenv shim without numpy: re-run with Debian's python3
    os.execv("/usr/bin/python3", ["/usr/bin/python3"] + sys.argv)

import time, sys
import numpy as np
import scipy.sparse as sp
import scipy.sparse.linalg as spla
from models import MODELS


def flow(model, x, mode, tau, hmax=0.01):
    """Forward trajectories of single points to time tau with guard detection (vectorised RK4)."""
    x = x.copy(); mode = mode.copy()
    nsub = max(1, int(np.ceil(tau / hmax))); h = tau / nsub
    def rk4(x, mode, h):
        out = np.empty_like(x)
        for k in range(len(model.modes)):
            i = mode == k
            if not i.any(): continue
            y = x[i]; f = lambda z: model.X(k, z)
            hh = h[i][:, None] if np.ndim(h) else h
            k1 = f(y); k2 = f(y + 0.5 * hh * k1); k3 = f(y + 0.5 * hh * k2); k4 = f(y + hh * k3)
            out[i] = y + hh / 6 * (k1 + 2 * k2 + 2 * k3 + k4)
        return out
    for _ in range(nsub):
        xn = rk4(x, mode, h)
        done = np.zeros(len(x), bool)
        for g in model.guards:
            i = np.nonzero((mode == g.frm) & ~done)[0]
            if len(i) == 0: continue
            s0 = g.s(x[i]); s1 = g.s(xn[i])
            cr = (g.dir * s0 < 0) & (g.dir * s1 >= 0)
            i = i[cr]
            if len(i) == 0: continue
            lo = np.zeros(len(i)); hi = np.ones(len(i))          # bisection on the crossing fraction
            for _ in range(40):
                mid = 0.5 * (lo + hi)
                sm = g.s(rk4(x[i], mode[i], mid * h))
                a = g.dir * sm >= 0
                hi = np.where(a, mid, hi); lo = np.where(a, lo, mid)
            xc = rk4(x[i], mode[i], hi * h)
            y = g.reset(xc); mode[i] = g.to
            xn[i] = rk4(y, mode[i], (1 - hi) * h)
            done[i] = True
        x = xn
    return x, mode


def ulam(model, N, M, tau):
    lo, hi = model.lo[0], model.hi[0]; dx = (hi - lo) / N; K = len(model.modes)
    sub = (np.arange(M) + 0.5) / M
    x0 = (lo + dx * (np.arange(N)[:, None] + sub[None, :])).ravel()[:, None]
    rows, cols, vals = [], [], []
    for k in range(K):
        x1, m1 = flow(model, x0, np.full(len(x0), k), tau)
        j = np.floor((x1[:, 0] - lo) / dx).astype(int)
        ok = (j >= 0) & (j < N)
        src = np.repeat(np.arange(N), M) + k * N
        rows.append(m1[ok] * N + j[ok]); cols.append(src[ok]); vals.append(np.full(ok.sum(), 1.0 / M))
    P = sp.csr_matrix((np.concatenate(vals), (np.concatenate(rows), np.concatenate(cols))), shape=(K * N, K * N))
    lam, v = np.linalg.eig(P.toarray())                 # dense: the spectrum clusters near |z| = 1
    o = np.argsort(-np.abs(lam)); lam, v = lam[o], v[:, o]
    u = np.real(v[:, 0]); u /= u.sum() * dx
    return u, lam, dx


def errors(model, u, N, dx):
    lo = model.lo[0]; errs = []
    e = lo + dx * np.arange(N + 1)
    q = (np.arange(64) + 0.5) / 64
    jumps = np.array(model.jumps[0] if model.jumps[0] else [np.inf])
    for k in range(len(model.modes)):
        xs = (e[:-1, None] + dx * q[None, :])
        ex = model.exact(k, xs.reshape(-1, 1)).reshape(N, 64).mean(1)       # exact cell averages
        has_jump = np.array([np.any((jumps > e[i] + 1e-12) & (jumps < e[i + 1] - 1e-12)) for i in range(N)])
        uk = u[k * N:(k + 1) * N]
        errs.append(np.sum(np.abs(uk - ex)[~has_jump]) / np.sum(np.abs(ex)[~has_jump]))
    return errs


if __name__ == "__main__":
    runs = [("thermostat", 280, M, tau) for tau in (0.005, 0.05, 0.2) for M in (4, 64, 1024)]
    runs += [("thermostat", N, 1024, 0.05) for N in (70, 140, 560)]
    runs += [("sawtooth", 400, M, 0.05) for M in (4, 64, 1024)] + [("sawtooth", 400, 1024, 0.2)]
    runs += [("sawtooth", N, 1024, 0.05) for N in (100, 200, 800)]
    runs += [("fire", 400, 1024, 0.05), ("sawtooth", 100, 8192, 0.05), ("sawtooth", 400, 8192, 0.05)]
    print("| model | cells/mode N | samples M | tau | rel L1 per mode | lambda1 | lambda2 (modulus, arg) | time s |")
    print("|---|---|---|---|---|---|---|---|")
    for name, N, M, tau in runs:
        t = time.time(); m = MODELS[name]()
        u, lam, dx = ulam(m, N, M, tau); e = errors(m, u, N, dx)
        print("| %s | %d | %d | %g | %s | %.12f | %.6f, %.5f | %.1f |" % (name, N, M, tau, " ".join("%.2e" % x for x in e),
              abs(lam[0]), abs(lam[1]), abs(np.angle(lam[1])), time.time() - t)); sys.stdout.flush()
