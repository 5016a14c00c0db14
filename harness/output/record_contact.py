"""Contact content of the recording (runs with interaction): force series under ``plots/forces/*``; the
contact points and forces ON the arm as arrows under ``world/contact/*`` every `CONTACT_EVERY` steps
(the run's largest force `ARROW_LENGTH` long, `ARROW_FRONT` in front of the arm); the operator's hand.
"""

from __future__ import annotations

import numpy as np
import rerun as rr

from harness.loop.trajectory import Trajectory
from harness.output.scene import TIMELINE

CONTACT_EVERY = 10  # control steps between logged contact arrows
ARROW_LENGTH = 0.2  # m: the largest contact force of the run is drawn this long (a sixth of the arm)
ARROW_RADIUS = 0.006  # m, shaft radius of the force arrows
ARROW_FRONT = 0.06  # m towards the eye (world -Y): a push along the arm is not hidden in its boxes
_C_TRUE, _C_SENSED, _C_CONTACT = (200, 40, 40), (60, 120, 220), (230, 60, 30)


def force_series(traj: Trajectory) -> list[tuple[str, np.ndarray, list[str], list[tuple[int, int, int]]]]:
    """(entity, values (n, k), names, colours) of the force series, in `record._series`' format."""
    ft, fs = np.asarray(traj.F_true, dtype=float), np.asarray(traj.F_sensed, dtype=float)
    pen = np.maximum(0.0, -np.asarray(traj.contact, dtype=float)[:, 3:4])
    cols = [_C_TRUE, (240, 150, 40), _C_SENSED, (60, 200, 200)]
    return [
        ("plots/forces/F2", np.column_stack([ft[:, 2:4], fs[:, 2:4]]),
         ["F2 X true", "F2 Z true", "F2 X to law", "F2 Z to law"], cols),
        ("plots/forces/F1", np.column_stack([ft[:, 0:2], fs[:, 0:2]]),
         ["F1 X true", "F1 Z true", "F1 X to law", "F1 Z to law"], cols),
        ("plots/forces/penetration", pen, ["penetration [m]"], [_C_CONTACT]),
    ]


def max_contact_force(traj: Trajectory) -> float:
    """N, the largest contact force on the arm over `traj` (0 without contacts)."""
    pts = traj.contact_points
    if pts is None or not len(pts):
        return 0.0
    f = np.linalg.norm(np.asarray(pts, dtype=float)[:, :, 3:], axis=-1)
    return float(np.nanmax(f)) if np.isfinite(f).any() else 0.0


def arrow_scale(traj: Trajectory, fmax: float | None = None) -> float:
    """m per N of the contact-force arrows: the largest contact force (`fmax`, default: of `traj`) is
    ARROW_LENGTH long (ARROW_LENGTH per newton when no contact carries force)."""
    fmax = max_contact_force(traj) if fmax is None else fmax
    return ARROW_LENGTH / fmax if fmax > 0 else ARROW_LENGTH


def log_contacts(rec: rr.RecordingStream, traj: Trajectory, master_base: np.ndarray, scale: float) -> None:
    """Contact points and force arrows (world frame, `scale` m per N) and the operator's hand point."""
    pts = traj.contact_points
    hand = traj.hand
    op = hand is not None and np.any(hand != 0)
    for k in range(0, len(traj), CONTACT_EVERY):
        rec.set_time(TIMELINE, duration=float(traj.t[k]))
        if pts is not None:
            live = np.any(pts[k, :, 3:] != 0, axis=1)
            p, f = pts[k, live, :3], pts[k, live, 3:]
            rec.log("world/contact/points", rr.Points3D(p, radii=0.006, colors=_C_CONTACT))
            rec.log("world/contact/forces",
                    rr.Arrows3D(origins=p - [0.0, ARROW_FRONT, 0.0], vectors=f * scale, colors=_C_CONTACT,
                                radii=ARROW_RADIUS))
        if op:
            x = [master_base[0] + hand[k, 0], master_base[1], master_base[2] + hand[k, 1]]
            rec.log("world/operator/hand", rr.Points3D([x], radii=0.015, colors=(240, 200, 60)))
