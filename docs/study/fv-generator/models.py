"""Test models, written only with the kernels hybgen has per model:
flow X_m(x), guards (s_g, direction, from, to, reset Delta_g), box.  The closed
forms (exact_*) are used ONLY for measuring errors, never by the numerics.

x is an array of shape (n, dim).  X(m, x) returns (n, dim).
"""
import numpy as np


class Guard:
    def __init__(self, frm, to, s, direction, reset):
        self.frm, self.to, self.s, self.dir, self.reset = frm, to, s, direction, reset


class Model:
    pass


def thermostat(lo=0.8, hi=2.2):
    m = Model()
    m.name, m.dim, m.modes = "thermostat", 1, ["heat", "cool"]
    m.lo, m.hi = np.array([lo]), np.array([hi])
    m.X = lambda k, x: (4.0 - x) if k == 0 else -x
    m.guards = [Guard(0, 1, lambda x: x[:, 0] - 2.0, +1, lambda x: x.copy()),
                Guard(1, 0, lambda x: x[:, 0] - 1.0, -1, lambda x: x.copy())]
    c = 1.0 / np.log(3.0)                       # total mass 1
    def exact(k, x):
        t = x[:, 0]
        inside = (t >= 1.0) & (t <= 2.0)
        return np.where(inside, c / np.abs(4.0 - t if k == 0 else -t), 0.0)
    m.exact = exact
    m.jumps = [[1.0, 2.0]]                      # per axis, for excluding nodes on a jump
    m.period = np.log(3.0)
    return m


def sawtooth():
    m = Model()
    m.name, m.dim, m.modes = "sawtooth", 1, ["grow"]
    m.lo, m.hi = np.array([0.0]), np.array([1.0])
    m.X = lambda k, x: 1.0 + x
    m.guards = [Guard(0, 0, lambda x: x[:, 0] - 1.0, +1, lambda x: np.zeros_like(x))]
    m.exact = lambda k, x: 1.0 / (np.log(2.0) * (1.0 + x[:, 0]))
    m.jumps = [[]]
    m.period = np.log(2.0)
    return m


def fire(theta=0.8, lo=-0.1, hi=0.9):
    """integrate-and-fire-like: x' = 1 - x, reset x -> 0 at x = theta (box wider than cycle)."""
    m = Model()
    m.name, m.dim, m.modes = "fire", 1, ["sub"]
    m.lo, m.hi = np.array([lo]), np.array([hi])
    m.X = lambda k, x: 1.0 - x
    m.guards = [Guard(0, 0, lambda x: x[:, 0] - theta, +1, lambda x: np.zeros_like(x))]
    L = -np.log(1.0 - theta)
    m.exact = lambda k, x: np.where((x[:, 0] >= 0) & (x[:, 0] <= theta), 1.0 / (L * (1.0 - x[:, 0])), 0.0)
    m.jumps = [[0.0, theta]]
    m.period = L
    return m


def product(a, b):
    """Independent product of two 1-D hybrid systems (modes = pairs)."""
    m = Model()
    m.name, m.dim = a.name + "x" + b.name, 2
    na, nb = len(a.modes), len(b.modes)
    m.modes = [p + "/" + q for p in a.modes for q in b.modes]
    m.lo, m.hi = np.r_[a.lo, b.lo], np.r_[a.hi, b.hi]
    def X(k, x):
        i, j = divmod(k, nb)
        return np.c_[a.X(i, x[:, :1]), b.X(j, x[:, 1:])]
    m.X = X
    m.guards = []
    for g in a.guards:
        for j in range(nb):
            m.guards.append(Guard(g.frm * nb + j, g.to * nb + j, (lambda g: lambda x: g.s(x[:, :1]))(g), g.dir,
                                  (lambda g: lambda x: np.c_[g.reset(x[:, :1]), x[:, 1:]])(g)))
    for g in b.guards:
        for i in range(na):
            m.guards.append(Guard(i * nb + g.frm, i * nb + g.to, (lambda g: lambda x: g.s(x[:, 1:]))(g), g.dir,
                                  (lambda g: lambda x: np.c_[x[:, :1], g.reset(x[:, 1:])])(g)))
    def exact(k, x):
        i, j = divmod(k, nb)
        return a.exact(i, x[:, :1]) * b.exact(j, x[:, 1:])
    m.exact = exact
    m.jumps = [a.jumps[0], b.jumps[0]]
    m.period = None
    return m


MODELS = {"thermostat": thermostat, "sawtooth": sawtooth, "fire": fire}
