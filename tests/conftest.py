"""Shared test helpers."""

from __future__ import annotations

import numpy as np
import pytest

from harness.loop.trajectory import Trajectory

MASTER_LENGTHS = (0.6, 0.6)
MASTER_BASE = np.array([0.0, 0.0, 0.05])
SLAVE_BASE = np.array([1.5, 0.0, 0.0])
SECTION_BODIES = (9, 8, 8)  # 25 plant bodies, segment origins, base to tip


def _cc_point(q2: np.ndarray, section: int, frac: float) -> tuple[np.ndarray, np.ndarray]:
    """Task-space point and tangent angle at `frac` of `section` of a constant-curvature arm.

    Written independently of harness.output.record (arc by arc, rotation form) so the tests cross-check it.
    """
    n = q2.shape[0]
    p = np.zeros((n, 2))
    phi = np.zeros(n)
    for i in range(section + 1):
        f = frac if i == section else 1.0
        d, k = q2[:, i] * f, q2[:, 3 + i]
        theta = k * d
        # chord of an arc of length d and turning angle theta, direction phi + theta/2
        chord = np.where(np.abs(theta) < 1e-12, d, 2.0 * np.sin(theta / 2.0) / np.where(k == 0, 1.0, k))
        ang = phi + theta / 2.0
        p = p + chord[:, None] * np.stack([np.sin(ang), np.cos(ang)], axis=-1)
        phi = phi + theta
    return p, phi


def cc_shape(q2: np.ndarray, per_section: int = 12) -> np.ndarray:
    """(P, 2) backbone points of one q2 (6,) relative to the slave base (a `backbone_fn`)."""
    q2 = np.asarray(q2, dtype=float).reshape(1, 6)
    pts = [np.zeros(2)]
    for s in range(3):
        for j in range(1, per_section + 1):
            pts.append(_cc_point(q2, s, j / per_section)[0][0])
    return np.array(pts)


def make_trajectory(n: int = 1200, *, plant: bool = True, nb: int = 25, status: str = "ok",
                    message: str = "", dt: float = 1e-3, nan_tail: int = 0,
                    with_master_pos: bool = True) -> Trajectory:
    """Deterministic, kinematically consistent synthetic run (sin/cos content)."""
    t = np.arange(n) * dt
    q1 = np.stack([0.35 + 0.2 * np.sin(3.0 * t), -0.9 + 0.3 * np.cos(2.0 * t)], axis=-1)
    dq1 = np.stack([0.6 * np.cos(3.0 * t), -0.6 * np.sin(2.0 * t)], axis=-1)
    l1, l2 = MASTER_LENGTHS
    elbow = l1 * np.stack([np.sin(q1[:, 0]), np.cos(q1[:, 0])], axis=-1)
    x1 = elbow + l2 * np.stack([np.sin(q1.sum(1)), np.cos(q1.sum(1))], axis=-1)
    xd = np.stack([0.01 * np.sin(t), 1.0 + 0.01 * np.cos(t)], axis=-1)

    i3 = np.arange(3)
    d = 0.33 + 0.04 * np.sin(2.0 * t[:, None] + i3)
    k = 0.8 * np.sin(1.5 * t[:, None] + 0.7 * i3) + 0.1 * (i3 - 1)
    q2 = np.concatenate([d, k], axis=1)
    dq2 = np.gradient(q2, dt, axis=0) if n > 1 else np.zeros_like(q2)
    x2 = _cc_point(q2, 2, 1.0)[0]

    e1, e2 = xd - x1, x1 - x2
    grad = (lambda a: np.gradient(a, dt, axis=0)) if n > 1 else np.zeros_like
    beta = 0.05 + 0.04 * np.sin(5.0 * t) ** 2
    deN = np.stack([np.sin((j + 1) * t + j) for j in range(6)], axis=-1) * 1e-2
    T1 = np.stack([np.sin(t), np.cos(2 * t)], axis=-1) * 3.0
    T2 = np.stack([np.cos((j + 2) * t) * (j + 1) for j in range(6)], axis=-1)
    u2 = 0.1 * T2

    def world(x, base):
        return np.stack([base[0] + x[:, 0], np.full(len(x), base[1]), base[2] + x[:, 1]], axis=-1)

    extra = {}
    if plant:
        x2_plant = x2 + 0.002 * np.stack([np.sin(7 * t), np.cos(7 * t)], axis=-1)
        pos, quat = [], []
        for s, cnt in enumerate(SECTION_BODIES[:3]):
            for m in range(cnt):
                p, phi = _cc_point(q2, s, m / cnt)
                pos.append(world(p, SLAVE_BASE))
                quat.append(np.stack([np.cos(phi / 2), np.zeros(n), np.sin(phi / 2), np.zeros(n)], -1))
        body_pos = np.stack(pos, axis=1)[:, :nb]
        body_quat = np.stack(quat, axis=1)[:, :nb]
        extra = dict(x2_plant=x2_plant, body_pos=body_pos, body_quat=body_quat)
    if with_master_pos:
        extra["master_pos"] = np.stack(
            [world(np.zeros((n, 2)), MASTER_BASE), world(elbow, MASTER_BASE), world(x1, MASTER_BASE)], axis=1)

    traj = Trajectory(
        t=t, q1=q1, dq1=dq1, q2=q2, dq2=dq2, xd=xd, x1=x1, x2=x2, e1=e1, e2=e2,
        de1=grad(e1), de2=grad(e2), beta=beta, ya=np.exp(-beta), deN=deN, T1=T1, T2=T2, u2=u2,
        status=status, message=message,
        meta=dict(master_lengths=MASTER_LENGTHS, master_base=MASTER_BASE.copy(),
                  slave_base=SLAVE_BASE.copy(), length_range=(np.full(3, 0.3), np.full(3, 0.45)),
                  max_bend=np.pi / 2, backbone_fn=cc_shape),
        **extra,
    )
    if nan_tail:
        for name in ("q2", "x2", "e2", "beta", "T2", "x2_plant", "body_pos", "body_quat"):
            a = getattr(traj, name)
            if a is not None:
                a[-nan_tail:] = np.nan
    return traj


@pytest.fixture
def synthetic_trajectory():
    """Factory: synthetic_trajectory(n=1200, plant=True, nb=25, status="ok", nan_tail=0, ...)."""
    return make_trajectory


def trajectory_arrays(tr: Trajectory) -> dict[str, np.ndarray]:
    """Every array field of a Trajectory (time series, plant geometry, contact points), by name: for
    bit-identity checks between two runs."""
    return {k: v for k, v in vars(tr).items() if isinstance(v, np.ndarray)}


@pytest.fixture
def traj_arrays():
    """trajectory_arrays(tr) -> {field name: array} of every array field of a Trajectory."""
    return trajectory_arrays


# ---------------------------------------------------------------------------------------------
# tiers: plain `pytest` runs the fast tier (pyproject addopts: -m 'not slow'); `pytest -m slow` the slow
# one; `pytest -m "slow or not slow"` both.  The summary gives each tier's time (setup + call +
# teardown of its tests, summed), so one run of both tiers (.ci/run) reports both.
# ---------------------------------------------------------------------------------------------
_TIER_TIME: dict[str, list[float]] = {}


def pytest_runtest_logreport(report):
    tier = "slow" if "slow" in report.keywords else "fast"
    entry = _TIER_TIME.setdefault(tier, [0, 0.0])
    entry[1] += report.duration
    if report.when == "call":
        entry[0] += 1


def pytest_terminal_summary(terminalreporter):
    if _TIER_TIME:
        parts = [f"{tier} tier: {n} tests, {t:.0f} s" for tier, (n, t) in sorted(_TIER_TIME.items())]
        terminalreporter.write_line("tiers (test time, summed): " + "; ".join(parts))
