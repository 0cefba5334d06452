"""Prototype: the Liouville generator of a hybrid system discretised directly as a
conservative upwind finite-volume operator on a cut-cell tensor grid, with guard
flux coupling.  Invariant density = null vector of the generator (no time step).

Uses only the per-model kernels: X_m(x), guards (s_g, direction, from, to, reset).
Prototype restriction: guard surfaces and their reset images are axis-aligned
hyperplanes (true for every 1-D model and for products); see REPORT.md for the
general curved-guard cut-cell recipe.

order p = 1: first-order upwind; p = 2: linear upwind (stencil up-1, up);
p = 3: upwind-biased quadratic (stencil up-1, up, down).  Stencils never cross a
"wall" (guard cut, reset image, box end), so the density may jump there exactly.
"""
import numpy as np
import scipy.sparse as sp
import scipy.sparse.linalg as spla


def recon_weights(cells, xe):
    """Weights w with sum_j w_j * avg_j(p) = p(xe) for polynomials p of degree len(cells)-1."""
    a = np.array([c[0] for c in cells], float); b = np.array([c[1] for c in cells], float)
    s = max(b - a)
    a_, b_ = (a - xe) / s, (b - xe) / s
    n = len(cells)
    A = np.empty((n, n))
    for q in range(n):
        A[:, q] = (b_ ** (q + 1) - a_ ** (q + 1)) / ((q + 1) * (b_ - a_))
    e0 = np.zeros(n); e0[0] = 1.0
    return np.linalg.solve(A.T, e0)


def _find_root_1d(f, a, b, n=64):
    xs = np.linspace(a, b, n + 1); fs = f(xs); out = []
    for i in range(n):
        if fs[i] == 0: out.append(xs[i])
        elif fs[i] * fs[i + 1] < 0:
            lo, hi = xs[i], xs[i + 1]
            for _ in range(80):
                mid = 0.5 * (lo + hi)
                if f(np.array([mid]))[0] * f(np.array([lo]))[0] <= 0: hi = mid
                else: lo = mid
            out.append(0.5 * (lo + hi))
    if fs[-1] == 0: out.append(xs[-1])
    return out


class Axis:
    """1-D cut-cell partition of one axis in one mode."""
    def __init__(self, lo, hi, nnodes, cuts, tol=1e-12):
        d = (hi - lo) / (nnodes - 1)
        self.nodes = lo + d * np.arange(nnodes)
        dual = np.r_[lo, lo + d * (np.arange(nnodes - 1) + 0.5), hi]
        pts = np.sort(np.r_[dual, [c for c in cuts if lo - tol <= c <= hi + tol]])
        keep = np.r_[True, np.diff(pts) > tol * max(1.0, abs(hi - lo))]
        self.e = pts[keep]
        self.e[0], self.e[-1] = lo, hi
        self.K = len(self.e) - 1
        walls = [0, self.K] + [int(np.argmin(np.abs(self.e - c))) for c in cuts if lo - tol <= c <= hi + tol]
        self.walls = sorted(set(walls))
        self.seg = np.searchsorted(self.walls, np.arange(self.K), side="right") - 1   # segment id of cell
        self.segrange = [(self.walls[i], self.walls[i + 1] - 1) for i in range(len(self.walls) - 1)]
        self.w = np.diff(self.e); self.c = 0.5 * (self.e[:-1] + self.e[1:])

    def stencil(self, start, p, cell):
        s0, s1 = self.segrange[self.seg[cell]]
        p = min(p, s1 - s0 + 1)
        start = min(max(start, s0), s1 - p + 1)
        return list(range(start, start + p))

    def face_recon(self, f, side, p):
        """Upwind reconstruction at face f (between cells f-1, f).  side=+1: flow to +, upwind f-1."""
        if side > 0:
            up = f - 1
            if up < 0: return None
            st = self.stencil(up - 1 if p >= 2 else up, p, up)
        else:
            up = f
            if up >= self.K: return None
            st = self.stencil(up - (p - 2) if p >= 3 else up, p, up)   # mirror of (up-1, up, up+1)
            if p == 2: st = self.stencil(up, 2, up)                      # (up, up+1)
        return up, st, recon_weights([(self.e[j], self.e[j + 1]) for j in st], self.e[f])

    def eval_matrix(self, p, jumps=()):
        """Cell averages -> node values (centred stencil in the node's segment)."""
        n = len(self.nodes); E = np.zeros((n, self.K))
        for i, x in enumerate(self.nodes):
            k = min(max(np.searchsorted(self.e, x, side="right") - 1, 0), self.K - 1)
            st = self.stencil(k - (p - 1) // 2, p, k)
            if p == 2 and x < self.c[k]: st = self.stencil(k - 1, 2, k)
            E[i, st] = recon_weights([(self.e[j], self.e[j + 1]) for j in st], x)
        return E


class FV:
    def __init__(self, model, nnodes, order=3):
        self.m, self.p = model, order
        dim, M = model.dim, len(model.modes)
        nnodes = np.atleast_1d(nnodes)
        ctr = 0.5 * (model.lo + model.hi)
        # --- locate the (axis-aligned) guard hyperplanes and their reset images
        self.ginfo = []
        cuts = [[[] for _ in range(dim)] for _ in range(M)]
        for g in model.guards:
            grad = np.array([(g.s((ctr + 1e-6 * np.eye(dim)[d])[None])[0] - g.s((ctr - 1e-6 * np.eye(dim)[d])[None])[0]) / 2e-6
                             for d in range(dim)])
            d = int(np.argmax(np.abs(grad)))
            assert np.sum(np.abs(grad) > 1e-8 * np.abs(grad[d])) == 1, "prototype: axis-aligned guards only"
            def line(t, d=d, g=g):
                x = np.tile(ctr, (len(t), 1)); x[:, d] = t; return g.s(x)
            roots = _find_root_1d(line, model.lo[d] - 1e-9, model.hi[d] + 1e-9)
            for c in roots:
                p0 = ctr.copy(); p0[d] = c
                img = g.reset(p0[None])[0]
                cuts[g.frm][d].append(c)
                # reset image hyperplane: axis along which the image of the guard plane is constant
                dd = d
                cuts[g.to][dd].append(img[dd])
                self.ginfo.append((g, d, c, np.sign(grad[d])))
        self.cuts = cuts
        self.axes = [[Axis(model.lo[d], model.hi[d], nnodes[d], cuts[k][d]) for d in range(dim)] for k in range(M)]
        self.shape = [tuple(a.K for a in self.axes[k]) for k in range(M)]
        self.size = [int(np.prod(s)) for s in self.shape]
        self.off = np.r_[0, np.cumsum(self.size)]
        self.N = int(self.off[-1])
        vol = []
        for k in range(M):
            v = np.ones(1)
            for a in self.axes[k]: v = np.multiply.outer(v, a.w)
            vol.append(v.ravel())
        self.vol = np.concatenate(vol)
        self.leak = 0
        self._assemble()

    def _cell_of(self, k, y):
        idx = []
        for d, a in enumerate(self.axes[k]):
            if y[d] < a.e[0] - 1e-12 or y[d] > a.e[-1] + 1e-12: return None
            idx.append(min(max(np.searchsorted(a.e, y[d], side="right") - 1, 0), a.K - 1))
        return self.off[k] + np.ravel_multi_index(tuple(idx), self.shape[k])

    def _assemble(self):
        m, p, dim = self.m, self.p, self.m.dim
        R, C, V = [], [], []
        for k in range(len(m.modes)):
            axes = self.axes[k]
            for d in range(dim):
                a = axes[d]
                others = [axes[q] for q in range(dim) if q != d]
                # transverse multi-indices and centres/areas
                if others:
                    grids = np.meshgrid(*[np.arange(o.K) for o in others], indexing="ij")
                    tidx = [g.ravel() for g in grids]
                    tc = [o.c[t] for o, t in zip(others, tidx)]
                    area = np.prod([o.w[t] for o, t in zip(others, tidx)], axis=0)
                    T = len(area)
                else:
                    tidx, tc, area, T = [], [], np.ones(1), 1
                guards_here = [(g, s) for (g, gd, c, s) in self.ginfo if g.frm == k and gd == d for c in [c] if True]
                for f in range(a.K + 1):
                    x = np.zeros((T, dim))
                    q = 0
                    for dd in range(dim):
                        if dd == d: x[:, dd] = a.e[f]
                        else: x[:, dd] = tc[q]; q += 1
                    v = m.X(k, x)[:, d]
                    # is this face a guard of mode k?
                    gface = None
                    for (g, gd, c, sg) in self.ginfo:
                        if g.frm == k and gd == d and abs(c - a.e[f]) < 1e-9 * (1 + abs(c)):
                            gface = (g, sg)
                    for side in (+1, -1):
                        sel = np.nonzero(v * side > 0)[0]
                        if len(sel) == 0: continue
                        rec = a.face_recon(f, side, p)
                        if rec is None: continue          # inflow through the box boundary: zero
                        up, st, w = rec
                        down = f if side > 0 else f - 1
                        for t in sel:
                            def flat(i1):
                                idx = []; q = 0
                                for dd in range(dim):
                                    if dd == d: idx.append(i1)
                                    else: idx.append(tidx[q][t]); q += 1
                                return self.off[k] + np.ravel_multi_index(tuple(idx), self.shape[k])
                            rate = abs(v[t]) * area[t]
                            src = flat(up); cols = [flat(j) for j in st]
                            dest = None
                            if gface is not None and np.sign(gface[1] * v[t]) == gface[0].dir:
                                g = gface[0]
                                y = g.reset(x[t:t + 1])[0]
                                Xy = m.X(g.to, y[None])[0]
                                y = y + 1e-9 * Xy / (np.linalg.norm(Xy) + 1e-300)   # downstream side of the image
                                dest = self._cell_of(g.to, y)
                                if dest is None: self.leak += 1
                            elif 0 <= down < a.K:
                                dest = flat(down)
                            for j, wj in zip(cols, w):
                                R.append(src); C.append(j); V.append(-rate * wj)
                                if dest is not None:
                                    R.append(dest); C.append(j); V.append(rate * wj)
        self.B = sp.csr_matrix((V, (R, C)), shape=(self.N, self.N))   # mass rate = B u
        self.L = sp.diags(1.0 / self.vol) @ self.B                   # generator on densities

    def invariant(self):
        """Null vector of B normalised to unit mass (bordered system)."""
        N = self.N
        w = self.vol
        A = sp.bmat([[self.B, sp.csr_matrix(w[:, None])], [sp.csr_matrix(w[None, :]), None]]).tocsc()
        rhs = np.zeros(N + 1); rhs[-1] = 1.0
        sol = spla.spsolve(A, rhs)
        self.u, self.sigma = sol[:N], sol[N]
        return self.u

    def nodes(self, u=None):
        u = self.u if u is None else u
        out = []
        for k in range(len(self.m.modes)):
            U = u[self.off[k]:self.off[k + 1]].reshape(self.shape[k])
            for d, a in enumerate(self.axes[k]):
                E = a.eval_matrix(self.p)
                U = np.moveaxis(np.tensordot(E, U, axes=([1], [d])), 0, d)
            out.append(U)
        return out

    def node_grid(self, k):
        g = np.meshgrid(*[a.nodes for a in self.axes[k]], indexing="ij")
        return np.stack([x.ravel() for x in g], axis=1)

    def jump_mask(self, k):
        """True at nodes lying on a jump (exact density discontinuous there)."""
        masks = []
        for d, a in enumerate(self.axes[k]):
            j = np.array(self.m.jumps[d])
            masks.append(np.array([len(j) > 0 and np.min(np.abs(j - x)) < 1e-9 for x in a.nodes]))
        g = np.meshgrid(*masks, indexing="ij")
        return np.logical_or.reduce([x.ravel() for x in g])

    def errors(self, U=None):
        U = self.nodes() if U is None else U
        errs = []
        for k in range(len(self.m.modes)):
            x = self.node_grid(k); ex = self.m.exact(k, x); keep = ~self.jump_mask(k)
            errs.append(np.sum(np.abs(U[k].ravel() - ex)[keep]) / np.sum(np.abs(ex)[keep]))
        return errs

    def spectrum(self, nev=8, sigma=None):
        if self.N <= 2500:
            mu = np.linalg.eigvals(self.L.toarray())
        else:
            mu = spla.eigs(self.L.tocsc(), k=nev, sigma=sigma if sigma is not None else 1e-3, return_eigenvectors=False)
        return mu[np.argsort(np.abs(mu))]
