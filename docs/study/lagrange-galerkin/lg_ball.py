#!/usr/bin/python3
"""A conservative Lagrange-Galerkin transfer step on the paper's elastic ball, against the
box-limited closed form at t = 10 (README.md beside this file). Not part of the build.

The density is u = sum_j u_j phi_j (bilinear hats on the grid). One step h:
    b_i = integral of phi_i * (T_h u)  = sum_j A_ij u_j,   A_ij = integral phi_i(T_h x) phi_j(x) dx,
    M u' = b,   M_ij = integral phi_i phi_j  (the consistent mass matrix),
so that the mass 1^T M u = sum_i b_i is carried exactly (sum_i phi_i = 1), and u' is the
L2 projection of the exactly transported density: no 1/h growth of the error. A_ij by S x S
points per grid cell, each carrying phi_j(x) times its area to the hats at T_h(x).
Variants: 'lumped' (M replaced by its row sums: the hat scheme's diffusion), 'fct' (the
consistent solve limited towards the lumped one, Zalesak's limiter: no negative values).

Run: python3 lg_ball.py N STEP [S] [lumped|fct]    e.g. python3 lg_ball.py 257 0.5 8
"""
import os, sys, time
try:
    import numpy as np, scipy.sparse as sp, scipy.sparse.linalg as spla
except ImportError:        # python3 = a pyenv shim without numpy: re-run with Debian's python3
    os.execv("/usr/bin/python3", ["/usr/bin/python3"] + sys.argv)

n = int(sys.argv[1]); step = float(sys.argv[2]); S = int(sys.argv[3]) if len(sys.argv) > 3 else 4
variant = sys.argv[4] if len(sys.argv) > 4 else "consistent"
T = 10.0
x = np.linspace(0, 2, n); p = np.linspace(-2, 2, n); hx = x[1] - x[0]; hp = p[1] - p[0]


def flow(X, P, t):
    """The elastic ball (m = g = 1) forward by t: phase tau since the last impact, period 2 v0."""
    E = np.maximum(0.5 * P**2 + X, 1e-300); v0 = np.sqrt(2 * E)
    tau = np.mod(v0 - P + t, 2 * v0)
    return v0 * tau - 0.5 * tau**2, v0 - tau


def u0(X, P):
    return np.exp(-(X - 1)**2 - P**2)


def exact(X, P, t):
    """Box-limited: after one period every orbit with E > 2 has left through x = 2 or |p| = 2."""
    E = np.maximum(0.5 * P**2 + X, 1e-300)
    xb, qb = flow(X, -P, t)          # backward = forward from (x, -p), then flip p
    return np.where(E <= 2.0, u0(xb, -qb), 0.0)


t0 = time.time()
g = (np.arange(S) + 0.5) / S
ca, cb = np.meshgrid(np.arange(n - 1), np.arange(n - 1), indexing="ij"); ca = ca.ravel(); cb = cb.ravel()
rows, cols, vals = [], [], []
b0 = np.zeros(n * n)
w = hx * hp / S**2
for sa in g:
    for sb in g:
        X = x[ca] + sa * hx; P = p[cb] + sb * hp
        src = [(ca * n + cb, (1 - sa) * (1 - sb)), ((ca + 1) * n + cb, sa * (1 - sb)),
               (ca * n + cb + 1, (1 - sa) * sb), ((ca + 1) * n + cb + 1, sa * sb)]
        for j, f in src:
            np.add.at(b0, j, w * f * u0(X, P))
        Y, Q = flow(X, P, step)
        inb = (Y >= 0) & (Y <= 2) & (Q >= -2) & (Q <= 2)   # else: outflow
        fy = np.clip(Y / hx, 0, n - 1 - 1e-12); fq = np.clip((Q + 2) / hp, 0, n - 1 - 1e-12)
        ia = np.floor(fy).astype(int); ib = np.floor(fq).astype(int); ra = fy - ia; rb = fq - ib
        tgt = [(ia * n + ib, (1 - ra) * (1 - rb)), ((ia + 1) * n + ib, ra * (1 - rb)),
               (ia * n + ib + 1, (1 - ra) * rb), ((ia + 1) * n + ib + 1, ra * rb)]
        for j, f in src:
            for i, fi in tgt:
                rows.append(i[inb]); cols.append(j[inb]); vals.append((w * f * fi)[inb])
A = sp.csr_matrix((np.concatenate(vals), (np.concatenate(rows), np.concatenate(cols))), shape=(n * n, n * n))


def mass1(h):
    d = np.full(n, 4 * h / 6); d[0] = d[-1] = 2 * h / 6; o = np.full(n - 1, h / 6)
    return sp.diags([o, d, o], [-1, 0, 1])


M = sp.kron(mass1(hx), mass1(hp)).tocsc()
ML = np.asarray(M.sum(axis=1)).ravel()
if variant == "lumped":
    M = sp.diags(ML).tocsc()
lu = spla.splu(M)
Moff = (M - sp.diags(M.diagonal())).tocoo(); I, J, mij = Moff.row, Moff.col, Moff.data


def fct(b):
    """Zalesak: the consistent solution's antidiffusive fluxes m_ij (u_i - u_j), limited so that
    every node stays within its neighbours' lumped values."""
    uH = lu.solve(b); uL = b / ML
    f = mij * (uH[I] - uH[J])
    umax = uL.copy(); umin = uL.copy()
    np.maximum.at(umax, I, uL[J]); np.minimum.at(umin, I, uL[J])
    Pp = np.zeros_like(uL); Pm = np.zeros_like(uL)
    np.add.at(Pp, I, np.maximum(f, 0)); np.add.at(Pm, I, np.minimum(f, 0))
    with np.errstate(divide="ignore", invalid="ignore"):
        Rp = np.where(Pp > 0, np.minimum(1, ML * (umax - uL) / Pp), 1.0)
        Rm = np.where(Pm < 0, np.minimum(1, ML * (umin - uL) / Pm), 1.0)
    alpha = np.where(f > 0, np.minimum(Rp[I], Rm[J]), np.minimum(Rm[I], Rp[J]))
    corr = np.zeros_like(uL); np.add.at(corr, I, alpha * f)
    return uL + corr / ML


u = lu.solve(b0)
m0 = ML @ u
t1 = time.time()
for k in range(int(round(T / step))):
    u = fct(A @ u) if variant == "fct" else lu.solve(A @ u)
Xn, Pn = np.meshgrid(x, p, indexing="ij"); ex = exact(Xn, Pn, T).ravel()


def wt(h):
    ww = np.full(n, h); ww[0] = ww[-1] = h / 2; return ww


W = np.outer(wt(hx), wt(hp)).ravel()
err = np.abs(u - ex) * W; tot = (ex * W).sum(); E = (0.5 * Pn**2 + Xn).ravel()
print("n %d, step %g, %d x %d points per cell, %s: assembly %.1f s, march %.1f s" %
      (n, step, S, S, variant, t1 - t0, time.time() - t1))
print("  mass %.6f -> %.6f, min %.3g, max %.3g" % (m0, ML @ u, u.min(), u.max()))
print("  relative L1 against the closed form at the nodes, t = 10: %.3e" % (err.sum() / tot))
for a, b in [(0, 0.8), (0.8, 1.8), (1.8, 1.95), (1.95, 2.0), (2.0, 2.1), (2.1, 9)]:
    m = (E >= a) & (E < b)
    print("    of it at %4.2f <= E < %4.2f: %.2e" % (a, b, err[m].sum() / tot))
