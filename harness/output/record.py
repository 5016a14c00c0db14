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
    world/slave/rod, world/slave/sections  Cosserat plant: rod centreline (line strip of the nodes) and
                                         the section boundaries (points), per step
    world/slave/backbone                 analytic constant-curvature backbone of the sensed q2
    world/slave/tip                      plant tip (x2_plant; analytic x2 on the analytic plant)
    world/desired/master, .../slave      the desired path x_d (static)
    world/slave/obstacles/NAME           the environment's objects (static solids; harness.output.obstacles)
    world/contact/points, .../forces     contact points and forces on the arm (record_contact)
    traces/desired, traces/master,       2-D tip traces in task space (each arm relative to its own base)
    traces/slave                         as (X, -Z) (2-D views have y down, so Z points up on screen)
    traces/obstacles/NAME                outlines of the environment's objects in the slave's task plane
    status                               run status and message (static text)

Positions are MuJoCo's world frame; a static `Transform3D` on world/master, world/slave (and the
desired paths, contacts and operator of each arm) moves each arm's base into the plane Y = 0, so both arms
are drawn in one plane (`harness.output.scene.display_offset`).

The blueprint and the scene geometry (colours, arm points, framing of the views) are
`harness.output.scene`.
"""

from __future__ import annotations

import warnings
from collections.abc import Iterator
from datetime import timedelta
from functools import cache
from pathlib import Path

import numpy as np
import pyarrow as pa
import rerun as rr
from rerun.chunk import RrdReader
from rerun.encodings import Vec3DBatch

from harness.config.textio import OutputError, atomic_path
from harness.loop.trajectory import Trajectory
from harness.output.geometry import (
    DEFAULT_MASTER_LENGTHS,
    backbone_points_world,
    cc_backbone,
    has_interaction,
    master_points,
    task_to_world,
    world_base,
)
from harness.output.obstacles import obstacle_face, obstacle_solid
from harness.output.record_contact import ARROW_LENGTH, arrow_scale, force_series, log_contacts
from harness.output.scene import (
    C_BACKBONE,
    C_DESIRED,
    C_MASTER,
    C_OBSTACLE,
    C_SECTIONS,
    C_SLAVE,
    C_X,
    C_X2,
    C_Z,
    C_Z2,
    TIMELINE,
    TRACE_POINT_RADIUS,
    box_half_size,
    build_blueprint,
    display_offset,
    trace_points,
)

APP_ID = "octarm_teleop"
MAX_STATIC_PATH_POINTS = 4000  # the static desired path is decimated to at most this many points
# `rerun rrd verify` costs ~ rows x points of each LineStrips3D chunk (measured: 20k rows of 25-point
# strips, 500-row chunks 4.3 s, 100-row chunks 1.1 s); strip chunks are capped at this many points.
STRIP_POINTS_PER_CHUNK = 2500
# Rate (Hz) of the 3-D geometry in `teleop run`'s recording (`geometry_rate`; time series stay at the
# control rate, bit-exact).  Measured on the paper run: every
# step (1 kHz) writes 22 MB, 100 Hz 8.4 MB in about half the time; 50 Hz saves no more (the scalars
# dominate) and 100 Hz is above a viewer's 60 fps playback.
DEFAULT_GEOMETRY_RATE = 100.0

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
    sec = list(C_SECTIONS)
    out = [
        ("plots/e1", traj.e1, ["e1 X", "e1 Z"], [C_X, C_Z]),
        ("plots/e2", traj.e2, ["e2 X", "e2 Z"], [C_X, C_Z]),
    ]
    if traj.x2_plant is not None:
        out.append(("plots/e2_plant", traj.e2_plant, ["e2 plant X", "e2 plant Z"], [C_X2, C_Z2]))
    out += [
        ("plots/beta", np.asarray(traj.beta).reshape(-1, 1), ["beta"], [C_SLAVE]),
        ("plots/ya", np.asarray(traj.ya).reshape(-1, 1), ["y_a"], [C_MASTER]),
        ("plots/deN_norm", np.linalg.norm(np.asarray(traj.deN, dtype=float), axis=-1), ["|e_N-dot|"], [C_X]),
        ("plots/q2", traj.q2, ["d1", "d2", "d3", "k1", "k2", "k3"], sec + sec),
        ("plots/T1", traj.T1, ["T1 a", "T1 b"], [C_X, C_Z]),
        ("plots/T2", traj.T2, ["T2 d1", "T2 d2", "T2 d3", "T2 k1", "T2 k2", "T2 k3"], sec + sec),
    ]
    if has_interaction(traj):
        out += force_series(traj)
    return [(e, np.asarray(v, dtype=np.float64).reshape(len(traj), len(nm)), nm, c) for e, v, nm, c in out]


def _status_text(traj: Trajectory) -> str:
    n = len(traj)
    span = f"{traj.t[0]:.6g} s .. {traj.t[-1]:.6g} s" if n else "no steps"
    lines = [
        "# Run status", "",
        f"* status: **{traj.status}**",
        f"* steps recorded: {n} ({span})",
        f"* plant: {_plant_name(traj)}",
    ]
    if has_interaction(traj):
        scale = arrow_scale(traj)
        lines.append(f"* contact force arrows: 1 N = {scale * 1e3:.3g} mm (the largest force is "
                     f"{ARROW_LENGTH * 1e3:.0f} mm long)")
    if traj.message:
        lines += ["", "```", str(traj.message), "```"]
    return "\n".join(lines) + "\n"


def _plant_name(traj: Trajectory) -> str:
    kind = (traj.meta or {}).get("plant")
    if kind == "cosserat":
        return "Cosserat rod"
    return "MuJoCo" if traj.x2_plant is not None else "analytic"


def write_recording(
    traj: Trajectory,
    path: str | Path,
    *,
    recording_id: str | None = None,
    block: int = 500,
    spatial_every: int = 1,
    geometry_rate: float | None = None,
) -> Path:
    """Write `traj` to the Rerun file `path` (parents created) and return the path.

    recording_id: Rerun recording id (None = a fresh random id; pass a fixed one to get files that
    `rerun rrd compare` equal). block: rows per chunk (line-strip chunks are further capped at
    STRIP_POINTS_PER_CHUNK points, since `rerun rrd verify` grows with rows x points per chunk).
    spatial_every: log the 3-D scene every k-th step (time series are always full rate).
    geometry_rate: Hz, if given (else traj.meta["geometry_rate"], if set): log the 3-D scene at (at
    least) this rate instead, i.e. every `geometry_every(traj, rate)`-th step (the final step is always
    logged; math.inf = every step).  `harness.api.run_scenario` sets DEFAULT_GEOMETRY_RATE.
    """
    if geometry_rate is None:
        geometry_rate = (traj.meta or {}).get("geometry_rate")
    if geometry_rate is not None:
        spatial_every = geometry_every(traj, geometry_rate)
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
    master_base, slave_base = world_base(meta, "master_base"), world_base(meta, "slave_base")

    # batches flushed by size only (never by the 200 ms timer): the same run gives the same chunks even on
    # a loaded machine (`rerun rrd compare`)
    rec = rr.RecordingStream(APP_ID, recording_id=recording_id,
                             batcher_config=rr.ChunkBatcherConfig(flush_tick=timedelta(days=1)))
    rec.save(tmp, default_blueprint=build_blueprint(traj))
    rec.set_log_time_enabled(False)
    try:
        log_static(rec, traj, master_base, slave_base)
        if n:
            log_series(rec, traj, block)
            log_spatial(rec, traj, master_base, slave_base, block, spatial_every)
            if has_interaction(traj):
                log_contacts(rec, traj, TIMELINE, master_base)
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


def geometry_every(traj: Trajectory, rate: float) -> int:
    """Steps between logged 3-D scenes for a display rate `rate` (Hz, > 0): floor(1 / (rate dt)) >= 1,
    so the logged rate is >= `rate`; dt = traj.meta["control_dt"], else the median step of traj.t."""
    rate = float(rate)
    if not rate > 0:
        raise ValueError(f"geometry_rate = {rate}: must be > 0 Hz")
    dt = (traj.meta or {}).get("control_dt")
    if dt is None:
        dt = float(np.median(np.diff(traj.t))) if len(traj) > 1 else 0.0
    if not (np.isfinite(dt) and dt > 0) or not np.isfinite(rate):
        return 1
    return max(1, int(np.floor(1.0 / (rate * float(dt)) + 1e-9)))


def log_static(rec: rr.RecordingStream, traj: Trajectory, master_base, slave_base) -> None:
    meta = traj.meta or {}
    rec.log("world", rr.ViewCoordinates.RIGHT_HAND_Z_UP, static=True)
    rec.log("status", rr.TextDocument(_status_text(traj), media_type=rr.MediaType.MARKDOWN), static=True)
    for entity, _, names, colors in _series(traj):
        rec.log(entity, rr.SeriesLines(names=names, colors=colors), static=True)
    # both arms drawn in the plane Y = 0 (`scene.display_offset`): the data stay in MuJoCo's world frame,
    # a static translation of each arm's entities moves them
    m_off, s_off = display_offset(meta, "master_base"), display_offset(meta, "slave_base")
    for entity, off in (("world/master", m_off), ("world/desired/master", m_off), ("world/operator", m_off),
                        ("world/slave", s_off), ("world/desired/slave", s_off), ("world/contact", s_off)):
        rec.log(entity, rr.Transform3D(translation=off), static=True)
    shown = [master_base + m_off, slave_base + s_off]
    if np.linalg.norm(shown[0] - shown[1]) < 0.05:  # one place: one label that can be read
        rec.log("world/bases", rr.Points3D([shown[1]], radii=0.02, colors=[C_SLAVE],
                                           labels=["master and slave base"]), static=True)
    else:
        rec.log("world/bases", rr.Points3D(shown, radii=0.02, colors=[C_MASTER, C_SLAVE],
                                           labels=["master base", "slave base"]), static=True)
    log_obstacles(rec, meta.get("environment") or (), slave_base)
    if len(traj):
        idx = _decimate(len(traj), MAX_STATIC_PATH_POINTS)
        xd = np.asarray(traj.xd, dtype=float)[idx]
        for name, base in (("master", master_base), ("slave", slave_base)):
            rec.log(f"world/desired/{name}",
                    rr.LineStrips3D([task_to_world(xd, base)], radii=0.0015, colors=C_DESIRED), static=True)
        rec.log("traces/desired", rr.LineStrips2D([_screen(xd)], radii=rr.Radius.ui_points(1.5),
                                                  colors=C_DESIRED), static=True)
    # styling of the per-step entities (static, combined with the temporal data at query time)
    rec.log("world/master/arm", rr.LineStrips3D.from_fields(radii=0.012, colors=C_MASTER), static=True)
    rec.log("world/master/tip", rr.Points3D.from_fields(radii=0.012, colors=C_MASTER), static=True)
    rec.log("world/slave/backbone", rr.LineStrips3D.from_fields(radii=0.004, colors=C_BACKBONE), static=True)
    rec.log("world/slave/tip", rr.Points3D.from_fields(radii=0.012, colors=C_SLAVE), static=True)
    if "centreline" in (traj.meta or {}).get("geometry", {}):
        rec.log("world/slave/rod", rr.LineStrips3D.from_fields(radii=0.008, colors=C_SLAVE), static=True)
        rec.log("world/slave/sections", rr.Points3D.from_fields(radii=0.014, colors=C_SECTIONS[1]),
                static=True)
    # the master trace drawn larger, under the slave's: both stay visible where they overlap
    rec.log("traces/master", rr.Points2D.from_fields(radii=TRACE_POINT_RADIUS, colors=C_MASTER,
                                                     draw_order=1.0), static=True)
    rec.log("traces/slave", rr.Points2D.from_fields(radii=rr.Radius.ui_points(1.5), colors=C_SLAVE,
                                                    draw_order=2.0), static=True)


def log_obstacles(rec: rr.RecordingStream, obstacles, slave_base) -> None:
    """The environment's objects (static): solids in the 3-D view under world/slave/obstacles (slave task
    frame placed at the slave base), outlines in the 2-D traces view under traces/obstacles."""
    for ob in obstacles:  # named by their entity path (a label would cover what touches them)
        solid = obstacle_solid(ob)
        solid_fill = rr.components.FillMode.Solid
        if solid is None:
            r = float(ob["size"][0])
            centre = task_to_world(np.asarray(ob["position"], dtype=float), slave_base)
            shape = rr.Ellipsoids3D(centers=[centre], half_sizes=[[r, r, r]], colors=[C_OBSTACLE],
                                    fill_mode=solid_fill)
        else:
            c, half, angle = solid
            turn = rr.RotationAxisAngle(axis=[0.0, 1.0, 0.0], angle=angle)
            shape = rr.Boxes3D(centers=[task_to_world(c, slave_base)], half_sizes=[half], colors=[C_OBSTACLE],
                               rotation_axis_angles=[turn], fill_mode=solid_fill)
        name = rr.escape_entity_path_part(str(ob["name"]))
        rec.log(f"world/slave/obstacles/{name}", shape, static=True)
        outline = rr.LineStrips2D([_screen(obstacle_face(ob))], colors=[C_OBSTACLE],
                                  radii=rr.Radius.ui_points(1.5))
        rec.log(f"traces/obstacles/{name}", outline, static=True)


def _screen(x: np.ndarray) -> np.ndarray:
    """Task-space (..., 2) [X, Z] to 2-D view coordinates [X, -Z] (2-D views have y pointing down)."""
    out = np.array(x, dtype=float)
    out[..., 1] *= -1.0
    return out


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


def log_series(rec: rr.RecordingStream, traj: Trajectory, block: int) -> None:
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


def log_spatial(rec, traj: Trajectory, master_base, slave_base, block: int, every: int) -> None:
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

    # (f) 2-D tip traces in task space
    _, x1_task, x2_task = trace_points(traj)
    for entity, x in (("traces/master", x1_task), ("traces/slave", x2_task)):
        _send(rec, entity, t, block, _flat(rr.Points2D.descriptor_positions(), rr.components.Position2DBatch,
                                           _f32(_screen(x[idx])), 1))

    # (b) plant bodies: oriented boxes at the bodies (they tile the chain; the tip point is (e))
    if traj.body_pos is not None:
        bpos = np.asarray(traj.body_pos, dtype=float)[idx]
        nb = bpos.shape[1]
        if nb:
            B, C = rr.Boxes3D, rr.components  # float32 in (Boxes3D.columns on all rows is ~10x slower)
            # the box size is constant over the run: logged once (static), poses per step
            half = box_half_size(bpos, meta).astype(np.float32)
            rec.log("world/slave/segments", B.from_fields(half_sizes=half, colors=C_SLAVE, radii=0.002),
                    static=True)
            boxes = _flat(B.descriptor_centers(), C.Translation3DBatch, _f32(bpos).reshape(-1, 3), nb)
            if traj.body_quat is not None:
                wxyz = np.asarray(traj.body_quat, dtype=float)[idx]
                quat = np.empty(wxyz.shape, dtype=np.float32)  # wxyz -> xyzw (Rerun stores float32)
                quat[..., :3] = wxyz[..., 1:]
                quat[..., 3] = wxyz[..., 0]
                boxes += _flat(B.descriptor_quaternions(), C.RotationQuatBatch, quat.reshape(-1, 4), nb)
            _send(rec, "world/slave/segments", t, block, boxes)

    # (b') Cosserat plant: rod centreline (world points of the nodes) and section boundaries
    geo = meta.get("geometry", {})
    if "centreline" in geo:
        _send_strips(rec, "world/slave/rod", t, block, np.asarray(geo["centreline"], dtype=float)[idx])
    if "sections" in geo:
        _send(rec, "world/slave/sections", t, block, _points_columns(np.asarray(geo["sections"])[idx]))

    # (c) analytic backbone of the sensed q2
    _send_strips(rec, "world/slave/backbone", t, block, backbone_points_world(traj, slave_base)[idx])


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


__all__ = ["APP_ID", "DEFAULT_GEOMETRY_RATE", "TIMELINE", "cc_backbone", "geometry_every", "read_series",
           "write_recording"]  # (scene geometry and blueprint: harness.output.scene)
