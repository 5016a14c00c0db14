"""Interaction-force kernels (numba-compatible): MuJoCo's contact sensors, the force sensing the laws see,
the operator's hand.  F = [F1x, F1z, F2x, F2z] N ON the robots at the tips, world X/Z, as in (1), (13),
(17)."""

from __future__ import annotations

import math

FORCE_MODES = {"exact": 0, "sensed": 1, "ignored": 2}
CONTACT_INFO = 5  # [n arm contacts, arm net Fx, Fz (on the arm), min distance (m), n tip contacts]
POINT_STRIDE = 10  # sensordata per contact point: found, force (contact frame, 3), pos (3), normal (3)


def filter_alpha(cutoff: float | None, dt: float) -> float:
    """Gain of the low-pass y += alpha (x - y) sampled every dt: alpha = 1 - exp(-2 pi fc dt) (1: none)."""
    return 1.0 if cutoff is None else 1.0 - math.exp(-2.0 * math.pi * cutoff * dt)


def read_contact(sensordata, adr, F2c, cinfo, pts):
    """From MuJoCo's contact sensors (`ContactMap.adr` (4,); empty: no environment, zeros): F2c (2,) the
    contact force ON the tip body [X, Z]; cinfo (CONTACT_INFO,); pts (np, 6) the largest contacts [pos
    xyz, force on the arm xyz] (frictionless: -f_n * normal)."""
    if adr.shape[0] == 0:
        F2c[0] = 0.0
        F2c[1] = 0.0
        for i in range(CONTACT_INFO):
            cinfo[i] = 0.0
        return
    a = adr[0]
    F2c[0] = -sensordata[a + 1]
    F2c[1] = -sensordata[a + 3]
    cinfo[4] = sensordata[a]
    b = adr[1]
    cinfo[0] = sensordata[b]
    cinfo[1] = -sensordata[b + 1]
    cinfo[2] = -sensordata[b + 3]
    c = adr[2]
    cinfo[3] = sensordata[c + 1] if sensordata[c] > 0.0 else 0.0
    p0 = adr[3]
    for r in range(pts.shape[0]):
        o = p0 + r * POINT_STRIDE
        found = sensordata[o] > 0.0
        fn = sensordata[o + 1]
        for j in range(3):
            pts[r, j] = sensordata[o + 4 + j] if found else 0.0
            pts[r, 3 + j] = -fn * sensordata[o + 7 + j] if found else 0.0


def sense_forces(Ftrue, k, mode, noise, std, alpha, delay, buf, filt, out):
    """What the laws get at step k from the true forces Ftrue (4,), into out (4,): mode 0 exact: Ftrue;
    2 ignored: 0; 1 sensed: Ftrue + std * noise[k] -> low-pass (gain alpha, state filt (4,), started at
    k = 0) -> delay of `delay` steps (ring buf (delay + 1, 4); the first sample until it arrives)."""
    if mode == 0:
        for i in range(4):
            out[i] = Ftrue[i]
        return
    if mode == 2:
        for i in range(4):
            out[i] = 0.0
        return
    nb = delay + 1
    slot = k % nb
    for i in range(4):
        x = Ftrue[i] + (std * noise[k, i] if std > 0.0 else 0.0)
        if k == 0:
            filt[i] = x
        else:
            filt[i] += alpha * (x - filt[i])
        buf[slot, i] = filt[i]
    src = (k - delay) % nb if k >= delay else 0
    for i in range(4):
        out[i] = buf[src, i]


def operator_target(targets, t, out):
    """Piecewise-linear target (2,) at time t of rows [t, X, Z] (held outside; none: out unchanged)."""
    nt = targets.shape[0]
    if nt == 0:
        return
    if t <= targets[0, 0]:
        out[0] = targets[0, 1]
        out[1] = targets[0, 2]
        return
    for r in range(1, nt):
        if t <= targets[r, 0]:
            s = (t - targets[r - 1, 0]) / (targets[r, 0] - targets[r - 1, 0])
            out[0] = targets[r - 1, 1] + s * (targets[r, 1] - targets[r - 1, 1])
            out[1] = targets[r - 1, 2] + s * (targets[r, 2] - targets[r - 1, 2])
            return
    out[0] = targets[nt - 1, 1]
    out[1] = targets[nt - 1, 2]


KERNELS = ("read_contact", "sense_forces", "operator_target")
