"""Write one run (`Trajectory`) to a Rerun `.rrd` file, in bulk on the duration timeline ``sim_time`` (s),
log time off (two writes of a run compare equal), and read series back.  Blueprint: `harness.output.scene`.
Entities (world: MuJoCo's, Z up; a static `Transform3D` moves each arm's base into the plane Y = 0):

    plots/e1, e2, e2_plant (X, Z) m (11), (16); beta (41); ya (29); deN_norm |e_N-dot| (23);
    q2 d (m), k (1/m); T1 N m; T2 [N, N m^2]; forces/* (runs with interaction)
    world/master/arm, tip            master base-elbow-tip strip, tip point
    world/slave/segments             plant bodies as oriented boxes (size static, pose per step)
    world/slave/rod, sections        Cosserat plant: centreline strip, section boundaries
    world/slave/backbone, tip        CC backbone of the sensed q2; plant tip (analytic x2 without one)
    world/desired/master, slave      the desired path x_d (static)
    world/slave/obstacles/NAME       the environment's objects (static; `geometry.obstacle_solid`)
    world/contact/points, forces     contacts and forces ON the arm, every CONTACT_EVERY steps
    world/operator/hand              the operator's hand
    traces/desired, master, slave, obstacles/NAME   2-D task-space traces as (X, -Z) (y down on screen)
    status                           run status and message (static text)
"""

from __future__ import annotations

import warnings
from datetime import timedelta
from pathlib import Path

import numpy as np
import pyarrow as pa
import rerun as rr
from rerun.chunk import RrdReader

from controllers.params import Q2_NAMES
from harness.config.textio import OutputError, atomic_path
from harness.loop.trajectory import Trajectory
from harness.output import geometry as geo
from harness.output import scene as sc
from harness.output.geometry import cc_backbone
from harness.output.scene import TIMELINE

APP_ID = "octarm_teleop"
MAX_STATIC_PATH_POINTS = 4000  # the static desired path is decimated to at most this many points
# `rerun rrd verify` costs ~ rows x points of each LineStrips3D chunk: strip chunks hold at most this many
STRIP_POINTS_PER_CHUNK = 2500
# Hz of the 3-D geometry in `teleop run`'s recording (time series stay at the control rate): on the paper
# run 8.4 MB in half the time of every step's 22 MB, above a viewer's 60 fps (docs: Performance)
DEFAULT_GEOMETRY_RATE = 100.0
FLUSH_TIMEOUT = 60.0  # s: the file sink must have written everything within this after the last log call
CONTACT_EVERY = 10  # control steps between logged contact arrows
ARROW_LENGTH = 0.2  # m: the largest contact force of the run is drawn this long (a sixth of the arm)
ARROW_RADIUS = 0.006  # m, shaft radius of the force arrows
ARROW_FRONT = 0.06  # m towards the eye (world -Y): a push along the arm is not hidden in its boxes
_C_TRUE, _C_SENSED, _C_CONTACT = (200, 40, 40), (60, 120, 220), (230, 60, 30)


def _ns(t: np.ndarray) -> np.ndarray:
    """Seconds -> nanoseconds, rounded to the nearest ns (rerun's own float path truncates)."""
    return np.round(np.asarray(t, dtype=float) * 1e9).astype(np.int64).astype("timedelta64[ns]")


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


def _series(traj: Trajectory) -> list[tuple[str, np.ndarray, list[str], list[tuple[int, int, int]]]]:
    """(entity, values (n, k), series names, colours) of every time series."""
    sec = list(sc.C_SECTIONS)
    xz = [sc.C_X, sc.C_Z]
    out = [("plots/e1", traj.e1, ["e1 X", "e1 Z"], xz), ("plots/e2", traj.e2, ["e2 X", "e2 Z"], xz)]
    if traj.x2_plant is not None:
        out.append(("plots/e2_plant", traj.e2_plant, ["e2 plant X", "e2 plant Z"], [sc.C_X2, sc.C_Z2]))
    out += [
        ("plots/beta", np.asarray(traj.beta).reshape(-1, 1), ["beta"], [sc.C_SLAVE]),
        ("plots/ya", np.asarray(traj.ya).reshape(-1, 1), ["y_a"], [sc.C_MASTER]),
        ("plots/deN_norm", np.linalg.norm(np.asarray(traj.deN, dtype=float), axis=-1), ["|e_N-dot|"],
         [sc.C_X]),
        ("plots/q2", traj.q2, list(Q2_NAMES), sec + sec),
        ("plots/T1", traj.T1, ["T1 a", "T1 b"], xz),
        ("plots/T2", traj.T2, ["T2 d1", "T2 d2", "T2 d3", "T2 k1", "T2 k2", "T2 k3"], sec + sec),
    ]
    if geo.has_interaction(traj):  # forces true and to the laws, penetration
        ft, fs = np.asarray(traj.F_true, dtype=float), np.asarray(traj.F_sensed, dtype=float)
        cols = [_C_TRUE, (240, 150, 40), _C_SENSED, (60, 200, 200)]
        out += [("plots/forces/F2", np.column_stack([ft[:, 2:4], fs[:, 2:4]]),
                 ["F2 X true", "F2 Z true", "F2 X to law", "F2 Z to law"], cols),
                ("plots/forces/F1", np.column_stack([ft[:, 0:2], fs[:, 0:2]]),
                 ["F1 X true", "F1 Z true", "F1 X to law", "F1 Z to law"], cols),
                ("plots/forces/penetration", np.maximum(0.0, -np.asarray(traj.contact, dtype=float)[:, 3:4]),
                 ["penetration [m]"], [_C_CONTACT])]
    return [(e, np.asarray(v, dtype=np.float64).reshape(len(traj), len(nm)), nm, c) for e, v, nm, c in out]


def _status_text(traj: Trajectory) -> str:
    n = len(traj)
    span = f"{traj.t[0]:.6g} s .. {traj.t[-1]:.6g} s" if n else "no steps"
    plant = "MuJoCo" if traj.x2_plant is not None else "analytic"
    if (traj.meta or {}).get("plant") == "cosserat":
        plant = "Cosserat rod"
    lines = ["# Run status", "", f"* status: **{traj.status}**", f"* steps recorded: {n} ({span})",
             f"* plant: {plant}"]
    if geo.has_interaction(traj):
        lines.append(f"* contact force arrows: 1 N = {arrow_scale(traj) * 1e3:.3g} mm (the largest force is "
                     f"{ARROW_LENGTH * 1e3:.0f} mm long)")
    if traj.message:
        lines += ["", "```", str(traj.message), "```"]
    return "\n".join(lines) + "\n"


def write_recording(traj: Trajectory, path: str | Path, *, recording_id: str | None = None, block: int = 500,
                    geometry_rate: float | None = None) -> Path:
    """Write `traj` to the Rerun file `path` (parents created, renamed into place when complete and read
    back) and return the path.  recording_id: None = a fresh random id (a fixed one gives files that
    `rerun rrd compare` equal); block: rows per chunk; geometry_rate: Hz of the 3-D scene (default
    traj.meta["geometry_rate"], else every step; `geometry_every`; the final step is always logged)."""
    if geometry_rate is None:
        geometry_rate = (traj.meta or {}).get("geometry_rate")
    every = 1 if geometry_rate is None else geometry_every(traj, geometry_rate)
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    with atomic_path(path) as tmp:  # the final name only ever holds a complete, readable file
        # batches flushed by size only (never by the 200 ms timer): the same run gives the same chunks
        rec = rr.RecordingStream(APP_ID, recording_id=recording_id,
                                 batcher_config=rr.ChunkBatcherConfig(flush_tick=timedelta(days=1)))
        rec.save(tmp, default_blueprint=sc.build_blueprint(traj))
        rec.set_log_time_enabled(False)
        try:
            log_static(rec, traj)
            if len(traj):
                log_steps(rec, traj, block, every)
            try:  # the file sink writes from its own thread: a write error (EFBIG, ENOSPC) shows only here
                rec.flush(timeout_sec=FLUSH_TIMEOUT)
            except RuntimeError as e:
                raise OutputError(f"cannot write {path}: the Rerun file sink failed ({e}; disk full or "
                                  "file size limit?)", path=str(path)) from None
        finally:
            rec.disconnect()  # completes the file
        try:  # Rerun's reader checks every frame against the file size and requires the footer
            with warnings.catch_warnings():
                warnings.simplefilter("error")
                RrdReader(tmp).stream()
        except Exception as e:  # noqa: BLE001 - any reader failure means a bad file
            raise OutputError(f"cannot write {path}: the written recording does not read back "
                              f"({' '.join(str(e).split())[:200]})", path=str(path)) from None
    return path


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


def log_static(rec: rr.RecordingStream, traj: Trajectory) -> None:
    """Everything static: view coordinates, status, series styles, arm placement, bases, obstacles, the
    desired paths and the styles of the per-step entities."""
    meta = traj.meta or {}
    master_base, slave_base = geo.world_base(meta, "master_base"), geo.world_base(meta, "slave_base")
    rec.log("world", rr.ViewCoordinates.RIGHT_HAND_Z_UP, static=True)
    rec.log("status", rr.TextDocument(_status_text(traj), media_type=rr.MediaType.MARKDOWN), static=True)
    for entity, _, names, colors in _series(traj):
        rec.log(entity, rr.SeriesLines(names=names, colors=colors), static=True)
    m_off, s_off = sc.display_offset(meta, "master_base"), sc.display_offset(meta, "slave_base")
    for entity, off in (("world/master", m_off), ("world/desired/master", m_off), ("world/operator", m_off),
                        ("world/slave", s_off), ("world/desired/slave", s_off), ("world/contact", s_off)):
        rec.log(entity, rr.Transform3D(translation=off), static=True)
    shown = [master_base + m_off, slave_base + s_off]
    if np.linalg.norm(shown[0] - shown[1]) < 0.05:  # one place: one label that can be read
        bases = rr.Points3D([shown[1]], radii=0.02, colors=[sc.C_SLAVE], labels=["master and slave base"])
    else:
        bases = rr.Points3D(shown, radii=0.02, colors=[sc.C_MASTER, sc.C_SLAVE],
                            labels=["master base", "slave base"])
    rec.log("world/bases", bases, static=True)
    log_obstacles(rec, meta.get("environment") or (), slave_base)
    if len(traj):
        n = len(traj)
        idx = np.arange(n) if n <= MAX_STATIC_PATH_POINTS else np.unique(
            np.linspace(0, n - 1, MAX_STATIC_PATH_POINTS).round().astype(int))
        xd = np.asarray(traj.xd, dtype=float)[idx]
        for name, base in (("master", master_base), ("slave", slave_base)):
            rec.log(f"world/desired/{name}", rr.LineStrips3D([geo.task_to_world(xd, base)], radii=0.0015,
                                                              colors=sc.C_DESIRED), static=True)
        rec.log("traces/desired", rr.LineStrips2D([_screen(xd)], radii=rr.Radius.ui_points(1.5),
                                                  colors=sc.C_DESIRED), static=True)
    # styling of the per-step entities (static, combined with the temporal data at query time)
    styles = [("world/master/arm", rr.LineStrips3D, 0.012, sc.C_MASTER),
              ("world/master/tip", rr.Points3D, 0.012, sc.C_MASTER),
              ("world/slave/backbone", rr.LineStrips3D, 0.004, sc.C_BACKBONE),
              ("world/slave/tip", rr.Points3D, 0.012, sc.C_SLAVE)]
    if "centreline" in meta.get("geometry", {}):
        styles += [("world/slave/rod", rr.LineStrips3D, 0.008, sc.C_SLAVE),
                   ("world/slave/sections", rr.Points3D, 0.014, sc.C_SECTIONS[1])]
    for entity, archetype, radius, color in styles:
        rec.log(entity, archetype.from_fields(radii=radius, colors=color), static=True)
    # the master trace drawn larger, under the slave's: both stay visible where they overlap
    rec.log("traces/master", rr.Points2D.from_fields(radii=sc.TRACE_POINT_RADIUS, colors=sc.C_MASTER,
                                                     draw_order=1.0), static=True)
    rec.log("traces/slave", rr.Points2D.from_fields(radii=rr.Radius.ui_points(1.5), colors=sc.C_SLAVE,
                                                    draw_order=2.0), static=True)


def log_obstacles(rec: rr.RecordingStream, obstacles, slave_base) -> None:
    """The environment's objects (static): solids in the slave's frame, outlines in the 2-D traces view."""
    for ob in obstacles:
        solid = geo.obstacle_solid(ob)
        fill = rr.components.FillMode.Solid
        if solid is None:
            r = float(ob["size"][0])
            centre = geo.task_to_world(np.asarray(ob["position"], dtype=float), slave_base)
            shape = rr.Ellipsoids3D(centers=[centre], half_sizes=[[r, r, r]], colors=[sc.C_OBSTACLE],
                                    fill_mode=fill)
        else:
            c, half, angle = solid
            shape = rr.Boxes3D(centers=[geo.task_to_world(c, slave_base)], half_sizes=[half],
                               colors=[sc.C_OBSTACLE], fill_mode=fill,
                               rotation_axis_angles=[rr.RotationAxisAngle(axis=[0.0, 1.0, 0.0], angle=angle)])
        name = rr.escape_entity_path_part(str(ob["name"]))
        rec.log(f"world/slave/obstacles/{name}", shape, static=True)
        outline = rr.LineStrips2D([_screen(geo.obstacle_face(ob))], colors=[sc.C_OBSTACLE],
                                  radii=rr.Radius.ui_points(1.5))
        rec.log(f"traces/obstacles/{name}", outline, static=True)


def _screen(x: np.ndarray) -> np.ndarray:
    """Task-space (..., 2) [X, Z] to 2-D view coordinates [X, -Z] (2-D views have y pointing down)."""
    out = np.array(x, dtype=float)
    out[..., 1] *= -1.0
    return out


def _f32(a: np.ndarray) -> np.ndarray:
    """float32, C-contiguous (what Rerun stores; the same rounding as Rerun's own conversion)."""
    return np.ascontiguousarray(a, dtype=np.float32)


def _send(rec: rr.RecordingStream, entity: str, t: np.ndarray, block: int, columns, per_row: int = 1) -> None:
    """send_columns in blocks of `block` rows; columns(sl) -> the archetype columns of the rows `sl`, with
    `per_row` instances a row."""
    for start in range(0, len(t), block):
        sl = slice(start, min(len(t), start + block))
        cols = columns(sl)
        if per_row != 1:
            cols = cols.partition(np.full(sl.stop - start, per_row))
        rr.send_columns(entity, indexes=[rr.TimeColumn(TIMELINE, duration=_ns(t[sl]))], columns=cols,
                        recording=rec)


def _send_points(rec, entity: str, t: np.ndarray, block: int, pos: np.ndarray) -> None:
    """Points3D of (rows, k, 3) positions, k points per row."""
    _send(rec, entity, t, block, lambda sl: rr.Points3D.columns(positions=_f32(pos[sl]).reshape(-1, 3)),
          pos.shape[1])


def _send_strips(rec: rr.RecordingStream, entity: str, t: np.ndarray, block: int, strips: np.ndarray) -> None:
    """One line strip per row, strips (rows, P, 3); chunks capped at STRIP_POINTS_PER_CHUNK points."""
    _send(rec, entity, t, max(1, min(block, STRIP_POINTS_PER_CHUNK // max(1, strips.shape[1]))),
          lambda sl: rr.LineStrips3D.columns(strips=_f32(strips[sl])))


def log_steps(rec: rr.RecordingStream, traj: Trajectory, block: int, every: int, fmax: float | None = None):
    """The time series, the 3-D scene and 2-D traces at every `every`-th step and the last one, and the
    contacts (force arrows: `fmax` N, default the largest of traj, is ARROW_LENGTH long)."""
    meta = traj.meta or {}
    master_base, slave_base = geo.world_base(meta, "master_base"), geo.world_base(meta, "slave_base")
    for entity, values, _, _ in _series(traj):
        _send(rec, entity, traj.t, block, lambda sl, v=values: rr.Scalars.columns(scalars=v[sl]))
    n = len(traj)
    idx = np.arange(0, n, every)
    if idx[-1] != n - 1:
        idx = np.append(idx, n - 1)  # always show the final state (e.g. where a run diverged)
    if len(idx) == n:
        idx = slice(None)  # every step: views instead of fancy-indexed copies
    t = np.asarray(traj.t, dtype=float)[idx]
    mpos = geo.master_points(traj, master_base)[idx]
    _send_strips(rec, "world/master/arm", t, block, mpos)
    _send_points(rec, "world/master/tip", t, block, mpos[:, 2:3])
    x2 = traj.x2_plant if traj.x2_plant is not None else traj.x2
    _send_points(rec, "world/slave/tip", t, block,
                 geo.task_to_world(np.asarray(x2, dtype=float)[idx], slave_base)[:, None, :])
    _, x1_task, x2_task = sc.trace_points(traj)
    for entity, x in (("traces/master", x1_task), ("traces/slave", x2_task)):
        pos = _f32(_screen(x[idx]))
        _send(rec, entity, t, block, lambda sl, pos=pos: rr.Points2D.columns(positions=pos[sl]))
    if traj.body_pos is not None and np.asarray(traj.body_pos).shape[1]:  # plant bodies: oriented boxes
        bpos = np.asarray(traj.body_pos, dtype=float)[idx]
        half = sc.box_half_size(bpos, meta).astype(np.float32)
        rec.log("world/slave/segments", rr.Boxes3D.from_fields(half_sizes=half, colors=sc.C_SLAVE,
                                                               radii=0.002), static=True)
        centers = _f32(bpos)
        q = None if traj.body_quat is None else _f32(np.asarray(traj.body_quat)[idx][..., [1, 2, 3, 0]])
        _send(rec, "world/slave/segments", t, block, lambda sl: rr.Boxes3D.columns(  # quaternions xyzw
            centers=centers[sl].reshape(-1, 3), quaternions=None if q is None else q[sl].reshape(-1, 4)),
            bpos.shape[1])
    geometry = meta.get("geometry", {})  # Cosserat plant: rod centreline and section boundaries (world)
    if "centreline" in geometry:
        _send_strips(rec, "world/slave/rod", t, block, np.asarray(geometry["centreline"], dtype=float)[idx])
    if "sections" in geometry:
        _send_points(rec, "world/slave/sections", t, block, np.asarray(geometry["sections"])[idx])
    _send_strips(rec, "world/slave/backbone", t, block, geo.backbone_points_world(traj, slave_base)[idx])
    if geo.has_interaction(traj):
        log_contacts(rec, traj, master_base, arrow_scale(traj, fmax))


def read_series(path: str | Path, entity: str) -> tuple[np.ndarray, np.ndarray]:
    """A `plots/...` series read back with Rerun's reader: (t s (n,), values (n, k)), sorted by time
    (stable).  Raises KeyError if the file has no scalar data for `entity`."""
    want = "/" + entity.strip("/")
    t_parts, v_parts = [], []
    for chunk in RrdReader(path).stream().to_chunks():
        if chunk.entity_path != want or chunk.is_static:
            continue
        batch = chunk.to_record_batch()
        if "Scalars:scalars" not in batch.schema.names or TIMELINE not in batch.schema.names:
            continue
        t_ns = batch.column(TIMELINE).cast(pa.int64()).to_numpy(zero_copy_only=False)
        col = batch.column("Scalars:scalars")
        lens = col.value_lengths().to_numpy(zero_copy_only=False)
        if len(lens) and np.any(lens != lens[0]):
            raise ValueError(f"{entity}: rows with different numbers of series in one chunk")
        t_parts.append(t_ns)
        v_parts.append(col.flatten().to_numpy(zero_copy_only=False).astype(np.float64).reshape(len(t_ns), -1))
    if not t_parts:
        raise KeyError(f"no scalar series for entity {entity!r} in {path}")
    t_ns, values = np.concatenate(t_parts), np.concatenate(v_parts, axis=0)
    order = np.argsort(t_ns, kind="stable")
    return t_ns[order] / 1e9, values[order]


__all__ = ["APP_ID", "DEFAULT_GEOMETRY_RATE", "TIMELINE", "cc_backbone", "geometry_every", "read_series",
           "write_recording"]
