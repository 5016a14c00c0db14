"""First bending mode of the Cosserat-rod slave: frequency and damping ratio from a released deflection.

    .venv/bin/python benchmarks/modal_cosserat.py                    # default material damping
    .venv/bin/python benchmarks/modal_cosserat.py --eta-b 0.03 0.1 --eta-a 3

The rod (paper slave parameters, 10 elements per section, servo rest strains straight: q2 = [L0, 0])
starts at rest bent by +0.3 1/m in every section and swings under gravity for 4 s with the rest
strains held.  f1 from the mean spacing of the first 8 zero crossings of the tip X about its final
value, zeta1 from the logarithmic decrement of the peaks one period apart (first and third
half-cycle).  A measurement, not a test.
"""

from __future__ import annotations

import argparse

import numpy as np

from controllers.params import SlaveParams
from harness.config.scenario import PlantConfig
from harness.plant.cosserat import CosseratSlave


def first_mode(eta_b: float, eta_a: float, seconds: float = 4.0) -> tuple[float, float]:
    p = SlaveParams()
    s = CosseratSlave(p, material_damping=([eta_b] * 3, [eta_a] * 3))
    q = np.array([*p.rest_lengths, 0.0, 0.0, 0.0])
    q0 = q.copy()
    q0[3:] += 0.3
    s.reset(q0)
    xs = []
    for _ in range(int(round(seconds / 1e-3))):
        s.step(q, 1e-3)
        xs.append(s.tip()[0])
    x = np.array(xs)
    x -= x[-len(x) // 4:].mean()
    zc = np.where(np.diff(np.sign(x)) != 0)[0]
    period = 2.0 * np.mean(np.diff(zc[:8])) * 1e-3
    peaks = [np.abs(x[zc[i]:zc[i + 1]]).max() for i in range(min(8, len(zc) - 1))]
    delta = np.log(peaks[0] / peaks[2])
    return 1.0 / period, delta / np.sqrt(4.0 * np.pi**2 + delta**2)


def main() -> None:
    d = PlantConfig()
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--eta-b", type=float, nargs="+", default=[d.bending_viscosity[0]], help="N m^2 s")
    ap.add_argument("--eta-a", type=float, default=d.extension_viscosity[0], help="N s")
    args = ap.parse_args()
    print("| eta_b [N m^2 s] | eta_a [N s] | f1 [Hz] | zeta1 |")
    print("|---:|---:|---:|---:|")
    for eb in args.eta_b:
        f1, z = first_mode(eb, args.eta_a)
        print(f"| {eb:g} | {args.eta_a:g} | {f1:.3f} | {z:.4f} |")


if __name__ == "__main__":
    main()
