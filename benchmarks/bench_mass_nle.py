"""A/B of the slave's M2/N2 kernel (`controllers.slave.mass_nle_kernel`): the per-section quadrature moments
by their power series (`controllers.moments.section_moments`, production) against the node loop alone
(the same kernel with the series declined), in one run, alternating, on random states.

    .venv/bin/python benchmarks/bench_mass_nle.py [--reps 12]

Both variants are compiled the way `harness.loop.fast` compiles the kernels (scratch arrays on the stack,
no numba runtime).  Prints per call medians, min-max and the paired per-repetition ratio, and the largest
relative difference between the two (the series gives the quadrature's own sums).  Asserts nothing.
"""

from __future__ import annotations

import argparse
import time
import types

import numba
import numpy as np

from controllers import cc, moments, slave
from controllers.params import SlaveParams
from harness.loop.native import scratch_intrinsics


def build(series: bool):
    mods = [cc, moments, slave]
    ns = {}
    for m in mods:
        ns.update({k: v for k, v in vars(m).items() if not k.startswith("__")})
    ns.update(scratch_intrinsics())
    compiled = {}
    for m in mods:
        for name in m.KERNELS:
            f = getattr(m, name)
            if name == "section_moments" and not series:
                compiled[name] = numba.njit(lambda th, f, nodes, Q: False)
                continue
            clone = types.FunctionType(f.__code__, ns, name, f.__defaults__, f.__closure__)
            compiled[name] = numba.njit(nogil=True, _nrt=False)(clone)
    ns.update(compiled)
    return compiled["mass_nle_kernel"]


@numba.njit
def _loop(fn, pk, Q, DQ, nodes, weights, M, N, reps):
    for _ in range(reps):
        for i in range(Q.shape[0]):
            fn(pk, Q[i], DQ[i], nodes, weights, M, N)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--reps", type=int, default=12)
    args = ap.parse_args()
    A, B = build(True), build(False)
    p = SlaveParams()
    pk = p.packed()
    nodes, weights = slave.gauss_legendre01(p.n_quad)
    rng = np.random.default_rng(0)
    M, N = np.empty((6, 6)), np.empty(6)
    inner = 20
    for label, maxth in (("|Theta| <= 1.0", 1.0), ("|Theta| <= pi/2 (max_bend)", np.pi / 2)):
        d = rng.uniform(0.3, 0.45, (1000, 3))
        Q = np.hstack([d, rng.uniform(-maxth, maxth, (1000, 3)) / d])
        DQ = rng.normal(size=(1000, 6))
        for fn in (A, B):
            _loop(fn, pk, Q, DQ, nodes, weights, M, N, 1)
        ta, tb = [], []
        for _ in range(args.reps):
            for fn, acc in ((A, ta), (B, tb)):
                t0 = time.perf_counter()
                _loop(fn, pk, Q, DQ, nodes, weights, M, N, inner)
                acc.append((time.perf_counter() - t0) / (inner * len(Q)) * 1e9)
        ta, tb = np.array(ta), np.array(tb)
        r = tb / ta
        Ma, Na, Mb, Nb = np.empty((6, 6)), np.empty(6), np.empty((6, 6)), np.empty(6)
        dm = 0.0
        for i in range(len(Q)):
            A(pk, Q[i], DQ[i], nodes, weights, Ma, Na)
            B(pk, Q[i], DQ[i], nodes, weights, Mb, Nb)
            dm = max(dm, np.abs(Ma - Mb).max() / np.abs(Mb).max(), np.abs(Na - Nb).max() / np.abs(Nb).max())
        print(f"{label}: series {np.median(ta):.0f} ns [{ta.min():.0f}-{ta.max():.0f}], node loop "
              f"{np.median(tb):.0f} ns [{tb.min():.0f}-{tb.max():.0f}] per call; paired ratio node/series "
              f"median {np.median(r):.2f} [{r.min():.2f}-{r.max():.2f}]; max rel difference {dm:.1e}")


if __name__ == "__main__":
    main()
