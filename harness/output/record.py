"""Write one run (`Trajectory`) to a Rerun `.rrd` file, and read time series back.

The file is written without a viewer (`RecordingStream.save`), with everything sent in bulk with
`rr.send_columns` in blocks of `block` rows on the duration timeline ``sim_time`` (seconds), log
time disabled so that two writes of the same run compare equal (`rerun rrd compare`).  Open it
with ``rerun FILE.rrd``; the default blueprint stored in the file lays out a 3-D view of both arms
and the time-series plots of the paper (Figs. 2-4) plus the extra channels.

Entity layout (task-space [X, Z] of a robot with base b maps to world (b_x + X, b_y, b_z + Z); world
is right-handed, Z up, like MuJoCo):

    plots/e1, plots/e2, plots/e2_plant   (X, Z) m          eq. (11), (16); plant tip = MuJoCo site
    plots/beta, plots/ya                 manipulability (41), y_a (29)
    plots/deN_norm                       |e_N-dot| (23)
    plots/q2                             d1..d3 (m), k1..k3 (1/m)
    plots/T1, plots/T2                   N m | [N, N m^2]
    world/master/arm, world/master/tip   line strip base-elbow-tip, tip point
    world/slave/segments                 plant bodies: oriented boxes sized like the segment rods (size
                                         static, pose per step; consecutive boxes tile the chain)
    world/slave/backbone                 analytic constant-curvature backbone of the sensed q2
    world/slave/tip                      plant tip (x2_plant; analytic x2 on the analytic plant)
    world/desired/master, .../slave      the desired path x_d (static)
    status                               run status and message (static text)
"""

from __future__ import annotations

import warnings
from collections.abc import Iterator
from functools import cache
from pathlib import Path

import numpy as np
import pyarrow as pa
import rerun as rr
import rerun.blueprint as rrb
from rerun.chunk import RrdReader
from rerun.encodings import Vec3DBatch

from harness.config.textio import OutputError, atomic_path
from harness.loop.trajectory import Trajectory

APP_ID = "octarm_teleop"
TIMELINE = "sim_time"
DEFAULT_MASTER_LENGTHS = (0.6, 0.6)  # m, paper Sec. VI (used only if traj.meta has no "master_lengths")
BACKBONE_POINTS_PER_SECTION = 10  # analytic backbone resolution when traj.meta has no "backbone"
MAX_STATIC_PATH_POINTS = 4000  # the static desired path is decimated to at most this many points
# `rerun rrd verify` costs ~ rows x points of each LineStrips3D chunk (measured: 20k rows of 25-point
# strips, 500-row chunks 4.3 s, 100-row chunks 1.1 s); strip chunks are capped at this many points.
STRIP_POINTS_PER_CHUNK = 2500

# RGB colours: X blue / Z orange as in most plotting defaults, master red-ish, slave green-ish.
_C_X, _C_Z = (31, 119, 180), (255, 127, 14)
_C_X2, _C_Z2 = (23, 190, 207), (214, 39, 40)
_C_SECTIONS = ((44, 160, 44), (148, 103, 189), (140, 86, 75))
_C_MASTER, _C_SLAVE, _C_BACKBONE = (220, 60, 60), (40, 160, 80), (250, 200, 40)
_C_DESIRED = (120, 120, 120)


# ---------------------------------------------------------------------------------------------
# geometry helpers (numpy, vectorized over steps)
# ---------------------------------------------------------------------------------------------
def _base(meta: dict, key: str) -> np.ndarray:
    b = meta.get(key)
    if b is None:
        return np.zeros(3)
    b = np.asarray(b, dtype=float).reshape(-1)
    if b.shape != (3,):
        raise ValueError(f"traj.meta[{key!r}] must be 3 numbers (world x, y, z), got shape {b.shape}")
    return b


def task_to_world(x: np.ndarray, base: np.ndarray) -> np.ndarray:
    """Task-space [X, Z] (..., 2), relative to `base`, to world (..., 3): (b_x + X, b_y, b_z + Z)."""
    x = np.asarray(x, dtype=float)
    out = np.empty(x.shape[:-1] + (3,))
    out[..., 0] = base[0] + x[..., 0]
    out[..., 1] = base[1]
    out[..., 2] = base[2] + x[..., 1]
    return out


def master_points(q1: np.ndarray, lengths, base: np.ndarray) -> np.ndarray:
    """World positions of master base, elbow, tip, (n, 3, 3), from joint angles q1 (n, 2).

    Angles from +Z towards +X (controllers.params.MasterParams):
    x1 = [l1 sin qa + l2 sin(qa + qb), l1 cos qa + l2 cos(qa + qb)].
    """
    q1 = np.asarray(q1, dtype=float).reshape(-1, 2)
    l1, l2 = (float(v) for v in np.asarray(lengths, dtype=float).reshape(2))
    a, ab = q1[:, 0], q1[:, 0] + q1[:, 1]
    elbow = np.stack([l1 * np.sin(a), l1 * np.cos(a)], axis=-1)
    tip = elbow + np.stack([l2 * np.sin(ab), l2 * np.cos(ab)], axis=-1)
    task = np.stack([np.zeros_like(elbow), elbow, tip], axis=1)  # (n, 3, 2)
    return task_to_world(task, base)


def cc_backbone(q2: np.ndarray, points_per_section: int = BACKBONE_POINTS_PER_SECTION) -> np.ndarray:
    """Planar constant-curvature backbone of q2 = [d1, d2, d3, k1, k2, k3], task space (n, 3 P + 1, 2).

    Base at the origin, tangent +Z, k > 0 bends toward +X (controllers.params.SlaveParams).  Along a
    section with tangent angle phi (from +Z toward +X) and arc s: p(s) = p0 + t sin(k s)/k
    + nrm (1 - cos(k s))/k with t = (sin phi, cos phi), nrm = (cos phi, -sin phi); phi += k d.
    Near-zero curvature uses the series limits (s, k s^2 / 2), so k = 0 is exact.
    """
    q2 = np.asarray(q2, dtype=float).reshape(-1, 6)
    n, P = q2.shape[0], int(points_per_section)
    u = np.linspace(0.0, 1.0, P + 1)[1:]  # fraction of the section, (P,)
    pts = np.empty((n, 3 * P + 1, 2))
    pts[:, 0] = 0.0
    p0 = np.zeros((n, 2))
    phi = np.zeros(n)
    for i in range(3):
        d, k = q2[:, i], q2[:, 3 + i]
        s = d[:, None] * u[None, :]  # (n, P)
        ks = k[:, None] * s
        small = np.abs(ks) < 1e-6
        with np.errstate(divide="ignore", invalid="ignore"):
            along = np.where(small, s * (1.0 - ks * ks / 6.0), np.sin(ks) / k[:, None])
            across = np.where(small, 0.5 * ks * s, (1.0 - np.cos(ks)) / k[:, None])
        t = np.stack([np.sin(phi), np.cos(phi)], axis=-1)[:, None, :]
        nrm = np.stack([np.cos(phi), -np.sin(phi)], axis=-1)[:, None, :]
        seg = p0[:, None, :] + t * along[..., None] + nrm * across[..., None]
        pts[:, 1 + i * P: 1 + (i + 1) * P] = seg
        p0 = seg[:, -1]
        phi = phi + k * d
    return pts


def _blocks(n: int, block: int) -> Iterator[slice]:
    for s in range(0, n, block):
        yield slice(s, min(n, s + block))


def _strip_block(block: int, points_per_strip: int) -> int:
    return max(1, min(block, STRIP_POINTS_PER_CHUNK // max(1, points_per_strip)))


def _ns(t: np.ndarray) -> np.ndarray:
    """Seconds -> nanoseconds, rounded to the nearest ns (rerun's own float path truncates)."""
    return np.round(np.asarray(t, dtype=float) * 1e9).astype(np.int64).astype("timedelta64[ns]")


def _decimate(n: int, m: int) -> np.ndarray:
    return np.arange(n) if n <= m else np.unique(np.linspace(0, n - 1, m).round().astype(int))


# ---------------------------------------------------------------------------------------------
# content
# ---------------------------------------------------------------------------------------------
def _series(traj: Trajectory) -> list[tuple[str, np.ndarray, list[str], list[tuple[int, int, int]]]]:
    """(entity, values (n, k), series names, colours) of every time series."""
    sec = list(_C_SECTIONS)
    out = [
        ("plots/e1", traj.e1, ["e1 X", "e1 Z"], [_C_X, _C_Z]),
        ("plots/e2", traj.e2, ["e2 X", "e2 Z"], [_C_X, _C_Z]),
    ]
    if traj.x2_plant is not None:
        out.append(("plots/e2_plant", traj.e2_plant, ["e2 plant X", "e2 plant Z"], [_C_X2, _C_Z2]))
    out += [
        ("plots/beta", np.asarray(traj.beta).reshape(-1, 1), ["beta"], [_C_SLAVE]),
        ("plots/ya", np.asarray(traj.ya).reshape(-1, 1), ["y_a"], [_C_MASTER]),
        ("plots/deN_norm", np.linalg.norm(np.asarray(traj.deN, dtype=float), axis=-1), ["|e_N-dot|"], [_C_X]),
        ("plots/q2", traj.q2, ["d1", "d2", "d3", "k1", "k2", "k3"], sec + sec),
        ("plots/T1", traj.T1, ["T1 a", "T1 b"], [_C_X, _C_Z]),
        ("plots/T2", traj.T2, ["T2 d1", "T2 d2", "T2 d3", "T2 k1", "T2 k2", "T2 k3"], sec + sec),
    ]
    return [(e, np.asarray(v, dtype=np.float64).reshape(len(traj), len(nm)), nm, c) for e, v, nm, c in out]


def _backbone_world(traj: Trajectory, slave_base: np.ndarray) -> np.ndarray | None:
    bb = traj.meta.get("backbone")
    if bb is not None:
        bb = np.asarray(bb, dtype=float)
        if bb.ndim != 3 or bb.shape[0] != len(traj) or bb.shape[2] != 3:
            warnings.warn(
                f"traj.meta['backbone'] has shape {bb.shape}, expected ({len(traj)}, P, 3); "
                "logging the analytic backbone of q2 instead", stacklevel=3)
        else:
            return bb
    return task_to_world(cc_backbone(traj.q2), slave_base)


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
                rrb.Spatial3DView(origin="world", contents="world/**", name="Master | slave (world, Z up)"),
                rrb.Spatial3DView(
                    origin="world", name="Tip traces",
                    contents=["world/master/tip", "world/slave/tip", "world/desired/**"],
                    time_ranges=trace_range),
                row_shares=[3, 1],
            ),
            rrb.Tabs(
                errors,
                ts(origin="plots/q2", name="q2: d (m), k (1/m)"),
                rrb.Vertical(ts(origin="plots/T1", name="T1 [N m]"),
                             ts(origin="plots/T2", name="T2 [N, N m^2]"), name="Torques"),
                rrb.TextDocumentView(origin="status", name="Run status"),
            ),
            column_shares=[1, 1],
        ),
        collapse_panels=False,
    )


def _status_text(traj: Trajectory) -> str:
    n = len(traj)
    span = f"{traj.t[0]:.6g} s .. {traj.t[-1]:.6g} s" if n else "no steps"
    lines = [
        "# Run status", "",
        f"* status: **{traj.status}**",
        f"* steps recorded: {n} ({span})",
        f"* plant: {'MuJoCo' if traj.x2_plant is not None else 'analytic'}",
    ]
    if traj.message:
        lines += ["", "```", str(traj.message), "```"]
    return "\n".join(lines) + "\n"


def write_recording(
    traj: Trajectory,
    path: str | Path,
    *,
    recording_id: str | None = None,
    block: int = 500,
    spatial_every: int = 1,
) -> Path:
    """Write `traj` to the Rerun file `path` (parents created) and return the path.

    recording_id: Rerun recording id (None = a fresh random id; pass a fixed one to get files that
    `rerun rrd compare` equal). block: rows per chunk (line-strip chunks are further capped at
    STRIP_POINTS_PER_CHUNK points, since `rerun rrd verify` grows with rows x points per chunk).
    spatial_every: log the 3-D scene every k-th step (time series are always full rate).
    """
    block, spatial_every = int(block), int(spatial_every)
    if block < 1 or spatial_every < 1:
        raise ValueError(f"block ({block}) and spatial_every ({spatial_every}) must be >= 1")
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    with atomic_path(path) as tmp:  # the final name only ever holds a complete, readable file
        _write(traj, tmp, path, recording_id, block, spatial_every)
        _check_readable(tmp, path)
    return path


FLUSH_TIMEOUT = 60.0  # s: the file sink must have written everything within this after the last log call


def _write(traj: Trajectory, tmp: Path, path: Path, recording_id, block: int, spatial_every: int) -> None:
    """Write the recording to `tmp`; a file-sink failure is a one-line OutputError naming `path`."""
    n = len(traj)
    meta = traj.meta or {}
    master_base, slave_base = _base(meta, "master_base"), _base(meta, "slave_base")
    rec = rr.RecordingStream(APP_ID, recording_id=recording_id)
    rec.save(tmp, default_blueprint=build_blueprint(traj))
    rec.set_log_time_enabled(False)
    try:
        _log_static(rec, traj, master_base, slave_base)
        if n:
            _log_series(rec, traj, block)
            _log_spatial(rec, traj, master_base, slave_base, block, spatial_every)
        # the file sink writes from its own thread: a write error (EFBIG, ENOSPC) shows only here
        try:
            rec.flush(timeout_sec=FLUSH_TIMEOUT)
        except RuntimeError as e:
            raise OutputError(f"cannot write {path}: the Rerun file sink failed ({e}; disk full or "
                              "file size limit?)", path=str(path)) from None
    finally:
        rec.disconnect()  # completes the file


def _check_readable(tmp: Path, path: Path) -> None:
    """Open the written file with Rerun's reader: every frame is checked against the file size and a
    missing footer (a file that was not completed) is an error too (~2 ms for a 5 MB file)."""
    try:
        with warnings.catch_warnings():
            warnings.simplefilter("error")
            RrdReader(tmp).stream()
    except Exception as e:  # noqa: BLE001 - any reader failure means a bad file
        raise OutputError(f"cannot write {path}: the written recording does not read back "
                          f"({' '.join(str(e).split())[:200]})", path=str(path)) from None


def _log_static(rec: rr.RecordingStream, traj: Trajectory, master_base, slave_base) -> None:
    rec.log("world", rr.ViewCoordinates.RIGHT_HAND_Z_UP, static=True)
    rec.log("status", rr.TextDocument(_status_text(traj), media_type=rr.MediaType.MARKDOWN), static=True)
    for entity, _, names, colors in _series(traj):
        rec.log(entity, rr.SeriesLines(names=names, colors=colors), static=True)
    rec.log("world/bases", rr.Points3D([master_base, slave_base], radii=0.02, colors=[_C_MASTER, _C_SLAVE],
                                       labels=["master base", "slave base"]), static=True)
    if len(traj):
        idx = _decimate(len(traj), MAX_STATIC_PATH_POINTS)
        xd = np.asarray(traj.xd, dtype=float)[idx]
        for name, base in (("master", master_base), ("slave", slave_base)):
            rec.log(f"world/desired/{name}",
                    rr.LineStrips3D([task_to_world(xd, base)], radii=0.0015, colors=_C_DESIRED), static=True)
    # styling of the per-step entities (static, combined with the temporal data at query time)
    rec.log("world/master/arm", rr.LineStrips3D.from_fields(radii=0.012, colors=_C_MASTER), static=True)
    rec.log("world/master/tip", rr.Points3D.from_fields(radii=0.012, colors=_C_MASTER), static=True)
    rec.log("world/slave/backbone", rr.LineStrips3D.from_fields(radii=0.004, colors=_C_BACKBONE), static=True)
    rec.log("world/slave/tip", rr.Points3D.from_fields(radii=0.012, colors=_C_SLAVE), static=True)


class _Arrow:
    """A ready pyarrow array as a Rerun `ComponentBatchLike` (and `TimeColumnLike` with a timeline)."""

    __slots__ = ("array", "timeline")

    def __init__(self, array: pa.Array, timeline: str = "") -> None:
        self.array = array
        self.timeline = timeline

    def as_arrow_array(self) -> pa.Array:
        return self.array

    def timeline_name(self) -> str:
        return self.timeline


def _flat(descriptor: rr.ComponentDescriptor, batch_cls, data, per_row: int) -> list:
    """[(descriptor, flat arrow values of all rows, items per row)] of one per-step component, converted
    once for every row by its Rerun batch class (what the archetype's `.columns()` uses, without its
    per-row partitioning work): each chunk then only slices the arrow array."""
    return [(descriptor, batch_cls(data).as_arrow_array(), per_row)]


def _send(rec: rr.RecordingStream, entity: str, t: np.ndarray, block: int, columns) -> None:
    """send_columns in blocks of rows; columns: `_flat` output for all rows (converted to arrow once,
    sliced per block, so the per-chunk cost is Rerun's own, not the conversion)."""
    times = rr.TimeColumn(TIMELINE, duration=_ns(t)).as_arrow_array()
    offsets: dict[tuple[int, int], np.ndarray] = {}
    for sl in _blocks(len(t), block):
        rows = sl.stop - sl.start
        cols = []
        for desc, values, k in columns:
            off = offsets.get((rows, k))
            if off is None:
                off = offsets[(rows, k)] = np.arange(0, (rows + 1) * k, k, dtype=np.int32)
            cols.append(rr.ComponentColumn(desc, _Arrow(values.slice(sl.start * k, rows * k)), offsets=off))
        rr.send_columns(entity, indexes=[_Arrow(times.slice(sl.start, rows), TIMELINE)], columns=cols,
                        recording=rec)


def _send_strips(rec: rr.RecordingStream, entity: str, t: np.ndarray, block: int, strips: np.ndarray) -> None:
    """One line strip per row, strips (rows, P, 3); chunks capped for `rerun rrd verify`."""
    _send(rec, entity, t, _strip_block(block, strips.shape[1]),
          _flat(rr.LineStrips3D.descriptor_strips(), rr.components.LineStrip3DBatch, _strips_arrow(strips),
                1))


def _strips_arrow(strips: np.ndarray) -> pa.Array:
    """(rows, P, 3) line strips as Rerun's LineStrip3D arrow array, built vectorized (Rerun's own
    numpy path loops over the rows in Python for the offsets)."""
    rows, P = strips.shape[:2]
    inner = Vec3DBatch(_f32(strips).reshape(-1, 3)).as_arrow_array()
    offsets = pa.array(np.arange(0, (rows + 1) * P, P, dtype=np.int32))
    return pa.ListArray.from_arrays(offsets, inner, type=_strip_type())


@cache
def _strip_type() -> pa.DataType:
    return rr.components.LineStrip3DBatch(np.zeros((1, 2, 3))).as_arrow_array().type


def _log_series(rec: rr.RecordingStream, traj: Trajectory, block: int) -> None:
    for entity, values, _, _ in _series(traj):
        _send(rec, entity, traj.t, block, _flat(rr.Scalars.descriptor_scalars(), rr.components.ScalarBatch,
                                                np.ascontiguousarray(values).reshape(-1), values.shape[1]))


def _points_columns(pos: np.ndarray) -> list:
    """Points3D columns for (rows, k, 3) positions (k points per row), see `_flat`."""
    return _flat(rr.Points3D.descriptor_positions(), rr.components.Position3DBatch, _f32(pos).reshape(-1, 3),
                 pos.shape[1])


def _f32(a: np.ndarray) -> np.ndarray:
    """float32, C-contiguous (what Rerun stores; the same rounding as Rerun's own conversion)."""
    return np.ascontiguousarray(a, dtype=np.float32)


def _log_spatial(rec, traj: Trajectory, master_base, slave_base, block: int, every: int) -> None:
    meta = traj.meta or {}
    n = len(traj)
    idx = np.arange(0, n, every)
    if idx[-1] != n - 1:
        idx = np.append(idx, n - 1)  # always show the final state (e.g. where a run diverged)
    if len(idx) == n:
        idx = slice(None)  # every step: views instead of fancy-indexed copies
    t = np.asarray(traj.t, dtype=float)[idx]

    # (a) master arm
    if traj.master_pos is not None:
        mpos = np.asarray(traj.master_pos, dtype=float)[idx].reshape(-1, 3, 3)
    else:
        lengths = meta.get("master_lengths", DEFAULT_MASTER_LENGTHS)
        mpos = master_points(np.asarray(traj.q1)[idx], lengths, master_base)
    _send_strips(rec, "world/master/arm", t, block, mpos)
    _send(rec, "world/master/tip", t, block, _points_columns(mpos[:, 2:3]))

    # (e) slave tip (plant site if present, else analytic x2)
    x2 = traj.x2_plant if traj.x2_plant is not None else traj.x2
    tip = task_to_world(np.asarray(x2, dtype=float)[idx], slave_base)[:, None, :]
    _send(rec, "world/slave/tip", t, block, _points_columns(tip))

    # (b) plant bodies: oriented boxes at the bodies (they tile the chain; the tip point is (e))
    if traj.body_pos is not None:
        bpos = np.asarray(traj.body_pos, dtype=float)[idx]
        nb = bpos.shape[1]
        if nb:
            B, C = rr.Boxes3D, rr.components  # float32 in (Boxes3D.columns on all rows is ~10x slower)
            # the box size is constant over the run: logged once (static), poses per step
            half = _box_half_size(bpos, meta).astype(np.float32)
            rec.log("world/slave/segments", B.from_fields(half_sizes=half, colors=_C_SLAVE, radii=0.002),
                    static=True)
            boxes = _flat(B.descriptor_centers(), C.Translation3DBatch, _f32(bpos).reshape(-1, 3), nb)
            if traj.body_quat is not None:
                wxyz = np.asarray(traj.body_quat, dtype=float)[idx]
                quat = np.empty(wxyz.shape, dtype=np.float32)  # wxyz -> xyzw (Rerun stores float32)
                quat[..., :3] = wxyz[..., 1:]
                quat[..., 3] = wxyz[..., 0]
                boxes += _flat(B.descriptor_quaternions(), C.RotationQuatBatch, quat.reshape(-1, 4), nb)
            _send(rec, "world/slave/segments", t, block, boxes)

    # (c) analytic backbone of the sensed q2
    _send_strips(rec, "world/slave/backbone", t, block, _backbone_world(traj, slave_base)[idx])


def _box_half_size(bpos: np.ndarray, meta: dict) -> np.ndarray:
    """Half extents (nb, 3) of the per-body boxes: traj.meta['body_half_size'] ((3,) for all bodies or
    (nb, 3), e.g. the MJCF segment geoms) or a fraction of the body spacing."""
    nb = bpos.shape[1]
    if meta.get("body_half_size") is not None:
        h = np.asarray(meta["body_half_size"], dtype=float)
        if h.shape == (nb, 3):
            return h
        return np.tile(h.reshape(3), (nb, 1))
    if nb >= 2:
        gaps = np.linalg.norm(np.diff(bpos[0], axis=0), axis=-1)
        gaps = gaps[np.isfinite(gaps) & (gaps > 0)]
        s = float(np.median(gaps)) if gaps.size else 0.04
    else:
        s = 0.04
    return np.tile(np.array([0.3, 0.15, 0.45]) * s, (nb, 1))


# ---------------------------------------------------------------------------------------------
# reading back
# ---------------------------------------------------------------------------------------------
def read_series(path: str | Path, entity: str) -> tuple[np.ndarray, np.ndarray]:
    """Read a `plots/...` series back with Rerun's own reader: (t seconds (n,), values (n, k)).

    Rows are sorted by time (stable).  Raises KeyError if the file has no scalar data for `entity`.
    """
    want = "/" + entity.strip("/")
    t_parts, v_parts = [], []
    for chunk in RrdReader(path).stream().to_chunks():
        if chunk.entity_path != want or chunk.is_static:
            continue
        batch = chunk.to_record_batch()
        names = batch.schema.names
        if "Scalars:scalars" not in names or TIMELINE not in names:
            continue
        t_ns = batch.column(TIMELINE).cast(pa.int64()).to_numpy(zero_copy_only=False)
        col = batch.column("Scalars:scalars")
        lens = col.value_lengths().to_numpy(zero_copy_only=False)
        if len(lens) and (np.any(lens != lens[0])):
            raise ValueError(f"{entity}: rows with different numbers of series in one chunk")
        flat = col.flatten().to_numpy(zero_copy_only=False).astype(np.float64)
        t_parts.append(t_ns)
        v_parts.append(flat.reshape(len(t_ns), -1))
    if not t_parts:
        raise KeyError(f"no scalar series for entity {entity!r} in {path}")
    k = {v.shape[1] for v in v_parts}
    if len(k) != 1:
        raise ValueError(f"{entity}: inconsistent number of series across chunks: {sorted(k)}")
    t_ns = np.concatenate(t_parts)
    values = np.concatenate(v_parts, axis=0)
    order = np.argsort(t_ns, kind="stable")
    return t_ns[order] / 1e9, values[order]


__all__ = ["APP_ID", "TIMELINE", "build_blueprint", "cc_backbone", "master_points", "read_series",
           "task_to_world", "write_recording"]
