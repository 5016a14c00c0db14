"""The scene of a run as the recording and the live viewer show it: colours, framing (3-D eye along +Y at
the arms' X-Z plane, 2-D tip traces, both showing the whole run) and the default blueprint."""

from __future__ import annotations

import numpy as np
import rerun as rr
import rerun.blueprint as rrb

from harness.loop.trajectory import Trajectory
from harness.output import geometry as geo
from harness.output.geometry import world_base

TIMELINE = "sim_time"  # the duration timeline of every recording

# RGB colours (X blue, Z orange, master red-ish, slave green-ish); view backgrounds distinct from each
# other and from the viewer's panels (tests locate the views on screenshots by them)
C_X, C_Z = (31, 119, 180), (255, 127, 14)
C_X2, C_Z2 = (23, 190, 207), (214, 39, 40)
C_SECTIONS = ((44, 160, 44), (148, 103, 189), (140, 86, 75))
C_MASTER, C_SLAVE, C_BACKBONE = (220, 60, 60), (40, 160, 80), (250, 200, 40)
C_DESIRED = (120, 120, 120)
BG_3D, BG_2D = (22, 27, 38), (30, 24, 38)

# framing of the default views (`frame_eye`, `frame_traces`)
VIEWER_FOV_Y = np.radians(55.0)  # vertical field of view of the viewer's 3-D eye (not a blueprint property)
FRAME_MIN_ASPECT = 0.75  # the eye distance fits the content in 3-D views down to this width / height
FRAME_MARGIN = 0.12  # fraction of the content extent added on each side
TRACE_POINT_RADIUS = rr.Radius.ui_points(2.5)  # on-screen size: the traces stay visible at any zoom
C_OBSTACLE = (150, 160, 190, 150)  # RGBA of the environment's objects: the arm stays visible behind them


def display_offset(meta: dict, key: str) -> np.ndarray:
    """World translation (3,) that moves an arm's base (meta[key]) into the plane Y = 0: both arms drawn in
    one plane, the slave's tip shows where the master's is whenever their task-space positions agree."""
    return np.array([0.0, -float(world_base(meta, key)[1]), 0.0])


def _finite(points: np.ndarray, dim: int) -> np.ndarray:
    p = np.asarray(points, dtype=float).reshape(-1, dim)
    return p[np.isfinite(p).all(axis=1)]


def scene_bounds(traj: Trajectory) -> tuple[np.ndarray, np.ndarray]:
    """World bounding box (lo (3,), hi (3,)) of both arms over the whole run: bases, master base-elbow-tip,
    slave bodies (padded by their box half-size), backbone, tips and the desired paths."""
    meta = traj.meta or {}
    mb, sb = world_base(meta, "master_base"), world_base(meta, "slave_base")
    parts = [mb, sb]
    pad = 0.02  # the base markers' radius
    if len(traj):
        parts.append(geo.master_points(traj, mb))
        xd, _, x2 = trace_points(traj)
        parts += [geo.task_to_world(x, base) for x, base in ((x2, sb), (xd, mb), (xd, sb))]
        if traj.body_pos is not None and np.asarray(traj.body_pos).size:
            parts.append(traj.body_pos)
            pad = max(pad, float(np.max(box_half_size(np.asarray(traj.body_pos), meta))))
        parts.append(geo.backbone_points_world(traj, sb))
    pts = [p for p in (_finite(q, 3) for q in parts) if len(p)]
    lo = np.min([p.min(axis=0) for p in pts], axis=0)
    hi = np.max([p.max(axis=0) for p in pts], axis=0)
    return lo - pad, hi + pad


def frame_eye(traj: Trajectory) -> rrb.EyeControls3D:
    """3-D eye looking along +Y at the X-Z plane (X right, Z up) that shows the whole `scene_bounds`
    with FRAME_MARGIN on each side, in views of aspect FRAME_MIN_ASPECT or wider."""
    lo, hi = scene_bounds(traj)
    c = 0.5 * (lo + hi)
    half_x, half_z = 0.5 * (hi - lo)[[0, 2]] * (1.0 + 2.0 * FRAME_MARGIN)
    dist = max(half_z, half_x / FRAME_MIN_ASPECT) / np.tan(0.5 * VIEWER_FOV_Y)  # from the nearest plane
    # both arms are drawn in the plane Y = 0 (`display_offset`); the nearest geometry is about half the
    # thickest body (or an obstacle's half depth) in front of it
    near = 0.5 * (hi[1] - lo[1] - abs(world_base(traj.meta or {}, "master_base")[1]
                                       - world_base(traj.meta or {}, "slave_base")[1]))
    if (traj.meta or {}).get("environment"):
        near = max(near, geo.OBSTACLE_HALF_DEPTH)
    c[1] = 0.0
    pos = [c[0], -max(near, 0.0) - dist, c[2]]
    return rrb.EyeControls3D(kind=rrb.Eye3DKind.Orbital, position=pos, look_target=[c[0], c[1], c[2]],
                             eye_up=[0.0, 0.0, 1.0])


def trace_points(traj: Trajectory) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Task-space (X, Z) of the desired path, the master tip and the slave tip (plant site if any)."""
    x2 = traj.x2_plant if traj.x2_plant is not None else traj.x2
    return (np.asarray(traj.xd, dtype=float).reshape(-1, 2), np.asarray(traj.x1, dtype=float).reshape(-1, 2),
            np.asarray(x2, dtype=float).reshape(-1, 2))


def frame_traces(traj: Trajectory) -> rrb.VisualBounds2D | None:
    """2-D bounds (screen x = X, y = -Z) of the desired path and both tip traces with FRAME_MARGIN on each
    side (at least 1 mm); None without finite data."""
    pts = _finite(np.concatenate(trace_points(traj), axis=0), 2) if len(traj) else np.zeros((0, 2))
    if not len(pts):
        return None
    lo, hi = pts.min(axis=0), pts.max(axis=0)
    pad = max(FRAME_MARGIN * float(np.max(hi - lo)), 1e-3)
    return rrb.VisualBounds2D(x_range=[lo[0] - pad, hi[0] + pad], y_range=[-hi[1] - pad, -lo[1] + pad])


def build_blueprint(traj: Trajectory) -> rrb.Blueprint:
    """Default layout: 3-D view of both arms | tabs of time-series views."""
    e2_contents = ["plots/e2"] + (["plots/e2_plant"] if traj.x2_plant is not None else [])
    ts = rrb.TimeSeriesView
    errors = rrb.Grid(
        ts(origin="plots/e1", name="e1 = x_d - x1 (11) [m]"),
        ts(origin="plots", contents=e2_contents, name="e2 = x1 - x2 (16) [m]"),
        ts(origin="plots/beta", name="beta, manipulability (41)"),
        ts(origin="plots/ya", name="y_a = exp(-k_y beta) (29)"),
        ts(origin="plots/deN_norm", name="|e_N-dot| (23)"),
        grid_columns=2, name="Errors & sub-task",
    )
    trace_range = rrb.VisibleTimeRange(
        TIMELINE, start=rr.TimeRangeBoundary.infinite(), end=rr.TimeRangeBoundary.cursor_relative())
    return rrb.Blueprint(
        rrb.Horizontal(
            rrb.Vertical(
                rrb.Spatial3DView(origin="world", contents="world/**", name="Master | slave (world, Z up)",
                                  eye_controls=frame_eye(traj), background=BG_3D),
                rrb.Spatial2DView(origin="traces", name="Tip traces, task space X-Z (grey: desired)",
                                  visual_bounds=frame_traces(traj), background=BG_2D,
                                  time_ranges=trace_range),
                row_shares=[3, 2],
            ),
            rrb.Tabs(
                errors,
                ts(origin="plots/q2", name="q2: d (m), k (1/m)"),
                rrb.Vertical(ts(origin="plots/T1", name="T1 [N m]"),
                             ts(origin="plots/T2", name="T2 [N, N m^2]"), name="Torques"),
                *([ts(origin="plots/forces", name="Forces [N]: true vs to the law")]
                  if geo.has_interaction(traj) else []),
                rrb.TextDocumentView(origin="status", name="Run status"),
            ),
            column_shares=[1, 1],
        ),
        rrb.SelectionPanel(state="collapsed"),  # room for the views; opens on a click on the arrow
        collapse_panels=False,
    )


def box_half_size(bpos: np.ndarray, meta: dict) -> np.ndarray:
    """Half extents (nb, 3) of the per-body boxes: traj.meta['body_half_size'] ((3,) for all bodies or
    (nb, 3), e.g. the MJCF segment geoms) or a fraction of the body spacing."""
    nb = bpos.shape[1]
    if meta.get("body_half_size") is not None:
        h = np.asarray(meta["body_half_size"], dtype=float)
        if h.shape == (nb, 3):
            return h
        return np.tile(h.reshape(3), (nb, 1))
    gaps = np.linalg.norm(np.diff(bpos[0], axis=0), axis=-1)  # empty for one body
    gaps = gaps[np.isfinite(gaps) & (gaps > 0)]
    s = float(np.median(gaps)) if gaps.size else 0.04
    return np.tile(np.array([0.3, 0.15, 0.45]) * s, (nb, 1))

