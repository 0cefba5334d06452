#!/usr/bin/python3
"""2-D product of two independent hybrid cycles: thermostat (x on [0.8, 2.2], 2 modes)
x sawtooth (y on [0, 1]) -> 2 modes, 4 guards.  Generator finite volumes (same code
as 1-D, dimension-by-dimension fluxes), invariant density error at nodes, Richardson
estimator, |lambda1|, and the eigenvalue near 2 pi i / ln 3.
Run: python3 fv2d.py [orders...]      (about 25 s);  python3 fv2d.py 3 fine  adds 281x201 (about 50 s)
"""
import os, sys
try:
    import numpy, scipy  # noqa: F401
except ImportError:        # python3 = a pyenv shim without numpy: re-run with Debian's python3
    os.execv("/usr/bin/python3", ["/usr/bin/python3"] + sys.argv)

import sys, time
import numpy as np
import scipy.sparse.linalg as spla
from models import thermostat, sawtooth, product
from fvgen import FV

GRIDS = [(71, 51), (141, 101), (281, 201)]
STEP = 0.05


FINE = "fine" in sys.argv


def main(orders):
    m = product(thermostat(), sawtooth())
    print("| model | p | nodes | unknowns | err per mode | D=||u_n-u_2n-1|| (est of fine) | ratio est/true | |lambda1|-1 | mu near 2 pi i/ln3 (err) | assemble+solve s |")
    print("|---|---|---|---|---|---|---|---|---|---|")
    ex = 2j * np.pi / np.log(3.0)
    for p in orders:
        prev = None
        grids = GRIDS if (p == 3 and FINE) else GRIDS[:2]
        for n in grids:
            t = time.time(); fv = FV(m, n, p); fv.invariant(); U = fv.nodes(); dt = time.time() - t
            e = fv.errors(U)
            mu = spla.eigs(fv.L.tocsc(), k=3, sigma=-1e-2, return_eigenvectors=False)
            lam1 = abs(np.exp(mu[np.argmin(abs(mu))] * STEP)) - 1
            if fv.N < 50000:
                mu2 = spla.eigs(fv.L.tocsc().astype(complex), k=2, sigma=ex - 0.01, return_eigenvectors=False)
                mu2 = mu2[np.argmin(abs(mu2 - ex))]; smu = "%.6f%+.6fi (%.1e)" % (mu2.real, mu2.imag, abs(mu2 - ex))
            else:
                smu = "-"
            if prev is not None:
                fa, Ua = prev
                D = max(np.sum(np.abs(Ua[k] - U[k][::2, ::2]).ravel()[~fa.jump_mask(k)]) /
                        np.sum(np.abs(U[k][::2, ::2]).ravel()[~fa.jump_mask(k)]) for k in range(len(U)))
                sD = "%.2e | %.2f" % (D, D / max(e))
            else:
                sD = "- | -"
            print("| thermostat x sawtooth | %d | %dx%d | %d | %s | %s | %.1e | %s | %.1f |" % (
                p, n[0], n[1], fv.N, " ".join("%.2e" % x for x in e), sD, lam1, smu, dt))
            sys.stdout.flush()
            prev = (fv, U)


if __name__ == "__main__":
    main([int(a) for a in sys.argv[1:] if a.isdigit()] or [1, 2, 3])
