#!/usr/bin/python3
"""(b)+(c)+(d) in 1-D: generator finite volumes of order 1, 2, 3 on the thermostat,
the sawtooth and the fire model (x' = 1 - x, reset 0 at 0.8, box [-0.1, 0.9]).
Prints: convergence table, error-estimator table, eigenvalue table.
Run: python3 fv1d.py        (about 30 s)
"""
import os, sys
try:
    import numpy, scipy  # noqa: F401
except ImportError:        # python3 = a pyenv shim without numpy: re-run with Debian's python3
    os.execv("/usr/bin/python3", ["/usr/bin/python3"] + sys.argv)

import time
import numpy as np
import scipy.sparse.linalg as spla
from models import MODELS
from fvgen import FV

SEQ = {"thermostat": [71, 141, 281, 561, 1121], "sawtooth": [51, 101, 201, 401, 801], "fire": [51, 101, 201, 401, 801]}
EXTRA = {"thermostat": [70, 140, 280, 560], "sawtooth": [], "fire": [50, 100, 200, 400]}   # guards not on nodes
STEP = 0.05                                          # hybgen's step, only to convert mu -> lambda


def solve(name, n, p):
    t = time.time(); fv = FV(MODELS[name](), n, p); fv.invariant(); U = fv.nodes(); dt = time.time() - t
    return fv, U, dt


def lowmu(fv, k=5):
    mu = spla.eigs(fv.L.tocsc(), k=k, sigma=-1e-2, return_eigenvectors=False, tol=1e-13)
    return mu[np.argsort(np.abs(mu))]


def reldiff(fa, Ua, fb, Ub):
    """relative L1 difference per mode at the coarse nodes (fine grid has 2n-1 nodes), jump nodes excluded."""
    out = []
    for k in range(len(Ua)):
        a = Ua[k].ravel(); b = Ub[k].ravel()[::2]; keep = ~fa.jump_mask(k)
        out.append(np.sum(np.abs(a - b)[keep]) / np.sum(np.abs(b)[keep]))
    return out


def main():
    print("## convergence (relative L1 per mode at nodes, nodes on a jump excluded)\n")
    print("| model | order p | nodes | unknowns | err (max over modes) | observed order | |lambda1|-1 (h=%.2f) | time s |" % STEP)
    print("|---|---|---|---|---|---|---|---|")
    store = {}
    for name in SEQ:
        for p in (1, 2, 3):
            prev = None
            for n in SEQ[name] + EXTRA[name]:
                fv, U, dt = solve(name, n, p); e = max(fv.errors(U))
                mu1 = lowmu(fv, 3)[0]
                lam1 = abs(np.exp(mu1 * STEP)) - 1
                order = "" if (prev is None or n not in SEQ[name]) else "%.2f" % np.log2(prev / e)
                print("| %s%s | %d | %d | %d | %.2e | %s | %.1e | %.2f |" % (name, "" if n in SEQ[name] else " (guards off-node)", p, n, fv.N, e, order, lam1, dt))
                if n in SEQ[name]: prev = e; store[(name, p, n)] = (fv, U, e)
    print("\n## error estimators (ratio = estimate / true error; want 1 <= ratio <= 10)\n")
    print("| model | p | n -> 2n-1 | true err fine | D = ||u_n - u_2n-1|| (est. of fine) | ratio | D*2^p/(2^p-1) (est. of coarse) | true err coarse | ratio | ||u_p - u_p+1|| (est. of u_p at 2n-1) | ratio |")
    print("|---|---|---|---|---|---|---|---|---|---|---|")
    for name in SEQ:
        for p in (1, 2, 3):
            s = SEQ[name]
            for a, b in zip(s[:-1], s[1:]):
                fa, Ua, ea = store[(name, p, a)]; fb, Ub, eb = store[(name, p, b)]
                D = max(reldiff(fa, Ua, fb, Ub))
                if p < 3:
                    fq, Uq, _ = store[(name, p + 1, b)]
                    Dq = max([np.sum(np.abs(x.ravel() - y.ravel())[~fb.jump_mask(k)]) / np.sum(np.abs(y.ravel())[~fb.jump_mask(k)])
                              for k, (x, y) in enumerate(zip(Ub, Uq))])
                    dq = "%.2e | %.2f" % (Dq, Dq / eb)
                else:
                    dq = "- | -"
                Dc = D * 2 ** p / (2 ** p - 1)
                print("| %s | %d | %d -> %d | %.2e | %.2e | %.2f | %.2e | %.2e | %.2f | %s |" % (name, p, a, b, eb, D, D / eb, Dc, ea, Dc / ea, dq))
    print("\n## eigenvalues of the generator (mu2 = first non-zero; exact mu2 = 2 pi i / period)\n")
    print("| model | p | n | mu2 | |mu2 - exact| | est |mu2(n/2) - mu2(n)| | ratio | period 2pi/Im mu2 rel err | Re mu2 | Re mu2 Richardson-extrapolated | decay claimed? | |lambda2| at h=%.2f | time s |" % STEP)
    print("|---|---|---|---|---|---|---|---|---|---|---|---|---|")
    for name in SEQ:
        m = MODELS[name](); ex = 2j * np.pi / m.period
        for p in (1, 2, 3):
            prev = None
            for n in SEQ[name]:
                t = time.time(); fv = store[(name, p, n)][0]; mu = lowmu(fv, 5); dt = time.time() - t
                mu2 = [z for z in mu[1:] if z.imag > 0][0]
                err = abs(mu2 - ex); T = 2 * np.pi / mu2.imag
                if prev is not None:
                    est = abs(prev - mu2); ratio = "%.2f" % (est / err)
                    re_x = mu2.real + (mu2.real - prev.real) / (2 ** p - 1)
                    estre = abs(mu2.real - prev.real)
                    claim = "yes (%.1e)" % -mu2.real if abs(mu2.real) > estre else "no: |Re| <= %.1e" % estre
                    sx = "%.2e" % re_x
                    se = "%.2e" % est
                else:
                    ratio = se = sx = claim = "-"
                print("| %s | %d | %d | %.6f%+.6fi | %.2e | %s | %s | %.1e | %.2e | %s | %s | %.9f | %.2f |" % (
                    name, p, n, mu2.real, mu2.imag, err, se, ratio, abs(T - m.period) / m.period, mu2.real, sx, claim,
                    abs(np.exp(mu2 * STEP)), dt))
                prev = mu2


if __name__ == "__main__":
    main()
