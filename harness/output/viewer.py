"""Live viewing of a run in Rerun, and opening recordings.

`LiveView` streams a run to a Rerun viewer while it is simulated: the simulation loop hands over each
finished chunk of control steps (`harness.loop.simulate(..., on_chunk=view.on_chunk)`, 1000 steps per
chunk on the MuJoCo plant, 250 on the analytic one) and the view logs them with the same entities,
colours and blueprint as the `.rrd` file (`harness.output.record`).  The file itself is still written
after the run by `harness.output.record.write_recording` (unchanged, byte-stable); the live stream is a
separate recording of the same application id.

    native  `rerun` viewer spawned as a separate process (it stays open after the run)
    web     gRPC server + Rerun's web viewer served over HTTP from this process (it lives as long as the
            process: `teleop run --view web` waits for Ctrl-C after the run)

The blueprint of the live stream frames the views from the first chunk and the scenario's whole desired
path (the run's full range of motion is known only at the end; the file's blueprint uses it).
"""

from __future__ import annotations

import shutil
import sys
import urllib.parse
import warnings
from pathlib import Path

import numpy as np
import rerun as rr

from harness.loop.trajectory import Trajectory
from harness.output import geometry, record, scene

VIEW_MODES = ("native", "web")
DESIRED_PATH_POINTS = 400


def rerun_executable() -> str | None:
    """The `rerun` CLI next to this Python (the venv's), else on PATH."""
    exe = Path(sys.executable).with_name("rerun")
    return str(exe) if exe.exists() else shutil.which("rerun")


class LiveView:
    """Streams chunks of a run to a viewer (or any sinks of `rec`); never raises into the simulation."""

    def __init__(self, rec: rr.RecordingStream, scn=None) -> None:
        self.rec = rec
        self.scn = scn
        self.url: str | None = None  # web viewer address (mode "web")
        self.chunks = 0
        self.failed: str | None = None
        self._first: Trajectory | None = None

    # -- construction ----------------------------------------------------------------------------
    @classmethod
    def open(cls, mode: str, scn=None, *, web_port: int | None = None, grpc_port: int | None = None,
             open_browser: bool = True) -> LiveView:
        """A live view on a spawned native viewer (mode "native") or a served web viewer ("web")."""
        if mode not in VIEW_MODES:
            raise ValueError(f"view mode {mode!r}: expected one of {VIEW_MODES}")
        rec = rr.RecordingStream(record.APP_ID)
        view = cls(rec, scn)
        if mode == "native":
            exe = rerun_executable()
            kw = {"executable_path": exe} if exe else {}
            rec.spawn(**kw)
        else:
            uri = rec.serve_grpc(grpc_port=grpc_port)
            rr.serve_web_viewer(web_port=web_port, open_browser=open_browser, connect_to=uri)
            view.url = f"http://127.0.0.1:{web_port or 9090}/?url={urllib.parse.quote(uri, safe='')}"
        return view

    @classmethod
    def to_file(cls, path: str | Path, scn=None) -> LiveView:
        """A live view whose stream goes to a file (what a viewer would receive; for tests)."""
        rec = rr.RecordingStream(record.APP_ID)
        rec.save(path)
        return cls(rec, scn)

    # -- streaming -------------------------------------------------------------------------------
    def on_chunk(self, part: Trajectory) -> None:
        """Log one chunk of steps (a `Trajectory` of those steps with the plant's meta)."""
        if self.failed or not len(part):
            return
        try:
            if self._first is None:
                self._first = part
                self._start(part)
            mb, sb = (geometry.world_base(part.meta, key) for key in ("master_base", "slave_base"))
            record.log_series(self.rec, part, 500)
            record.log_spatial(self.rec, part, mb, sb, 500, 1)
            self.chunks += 1
        except Exception as e:  # noqa: BLE001 - the viewer must never stop a run
            self.failed = f"{type(e).__name__}: {e}"
            warnings.warn(f"live view stopped: {self.failed}", stacklevel=2)

    def _start(self, part: Trajectory) -> None:
        framing = self._with_desired_path(part)
        self.rec.send_blueprint(scene.build_blueprint(framing))
        record.log_static(self.rec, framing, geometry.world_base(part.meta, "master_base"),
                           geometry.world_base(part.meta, "slave_base"))
        self.rec.log("status", rr.TextDocument("# Run status\n\n* status: **running**\n",
                                               media_type=rr.MediaType.MARKDOWN), static=True)

    def _with_desired_path(self, part: Trajectory) -> Trajectory:
        """`part` extended by the scenario's desired path over the whole run (for framing and the static
        desired path), the other rows repeating the last state."""
        if self.scn is None:
            return part
        from harness.loop.common import desired_at

        period = 2.0 * np.pi / max(abs(float(self.scn.trajectory.omega)), 1e-9)
        t = np.linspace(0.0, min(float(self.scn.duration), period), DESIRED_PATH_POINTS)
        xd = np.array([desired_at(self.scn, ti)[0] for ti in t])
        idx = np.concatenate([np.arange(len(part)), np.full(len(t), len(part) - 1)])
        fields = {k: getattr(part, k)[idx] for k in ("t", "q1", "dq1", "q2", "dq2", "x1", "x2", "e1", "e2",
                                                     "de1", "de2", "beta", "ya", "deN", "T1", "T2", "u2")}
        fields["xd"] = np.concatenate([part.xd, xd])
        extra = {k: (None if getattr(part, k) is None else getattr(part, k)[idx])
                 for k in ("x2_plant", "body_pos", "body_quat", "master_pos")}
        return Trajectory(**fields, **extra, status="running", message="", meta=dict(part.meta))

    def finish(self, traj: Trajectory) -> None:
        """After the run: final status text and desired path (static), and flush to the viewer."""
        if self._first is None or self.failed:
            return
        try:
            mb, sb = (geometry.world_base(traj.meta, key) for key in ("master_base", "slave_base"))
            record.log_static(self.rec, traj, mb, sb)
            self.rec.flush()
        except Exception as e:  # noqa: BLE001
            self.failed = f"{type(e).__name__}: {e}"
            warnings.warn(f"live view stopped: {self.failed}", stacklevel=2)

    def close(self) -> None:
        self.rec.flush()
        self.rec.disconnect()


def open_recording(path: str | Path, mode: str = "native") -> list[str]:
    """Command that opens a recording in a viewer (`rerun FILE` / `rerun --web-viewer FILE`)."""
    exe = rerun_executable() or "rerun"
    return [exe, *(["--web-viewer"] if mode == "web" else []), str(path)]
