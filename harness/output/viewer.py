"""Live viewing of a run in Rerun, and opening recordings.

`LiveView` streams each finished chunk of control steps (`harness.loop.simulate(..., on_chunk=)`) with the
entities, colours and blueprint of the `.rrd` file (`harness.output.record`, still written after the run):

    native  the Rerun viewer spawned on a local port (it stays open after the run); needs a display
    web     the viewer binary serving the web viewer (HTTP) and the data (gRPC), bound to 127.0.0.1 unless
            another host is asked for; it lives as long as this process (parent-death signal)

The live blueprint frames the views from the first chunk and the scenario's desired path.
"""

from __future__ import annotations

import contextlib
import dataclasses
import errno
import importlib.util
import ipaddress
import os
import re
import shutil
import signal
import socket
import subprocess
import sys
import tempfile
import time
import urllib.parse
import warnings
import webbrowser
from pathlib import Path
from typing import Any

import numpy as np
import rerun as rr

from harness.config.runtime import die_with_parent, parent_death_signal
from harness.loop.trajectory import Trajectory
from harness.output import geometry, record, record_contact, scene

VIEW_MODES = ("native", "web")
DESIRED_PATH_POINTS = 400
LOCALHOST = "127.0.0.1"
WEB_PORT = 9090  # Rerun's defaults: the web viewer's HTTP port and the data (gRPC) port
GRPC_PORT = 9876
START_TIMEOUT = 20.0  # s for a spawned viewer / viewer server to listen
NATIVE_SETTLE = 2.0  # s a native viewer must stay up after it listens (its window is created after that)
FLUSH_TIMEOUT = 10.0  # s for the live stream to reach the viewer at the end of a run


class ViewerUnavailable(RuntimeError):
    """The viewer could not be opened; the message is one line saying why and what to do instead."""


def has_display() -> bool:
    """Whether a native viewer window can be shown (macOS, Windows, or DISPLAY / WAYLAND_DISPLAY set)."""
    env = os.environ
    return sys.platform in ("darwin", "win32") or bool(env.get("DISPLAY") or env.get("WAYLAND_DISPLAY"))


def rerun_executable() -> str | None:
    """The viewer binary of the rerun-sdk wheel (`rerun_cli`), else `rerun` beside this Python or on PATH."""
    spec = importlib.util.find_spec("rerun_cli")
    if spec is not None and spec.origin:
        folder = Path(spec.origin).parent
        suffix = ".exe" if sys.platform == "win32" else ""
        for cand in (folder / "Rerun.app" / "Contents" / "MacOS" / "Rerun", folder / f"rerun{suffix}"):
            if cand.is_file() and os.access(cand, os.X_OK):
                return str(cand)
    exe = Path(sys.executable).with_name("rerun")
    return str(exe) if exe.exists() else shutil.which("rerun")


def is_loopback(host: str) -> bool:
    try:
        return ipaddress.ip_address(host).is_loopback
    except ValueError:
        return host == "localhost"


def _check_free(host: str, port: int, option: str) -> int:
    """`port` (0: any free port) if it can be bound on `host`, else ViewerUnavailable naming `option`."""
    family = socket.AF_INET6 if ":" in host else socket.AF_INET
    with socket.socket(family, socket.SOCK_STREAM) as s:
        try:
            s.bind((host, port))
        except socket.gaierror as e:
            raise ViewerUnavailable(f"--view-host {host}: not an address ({e.strerror or e})") from None
        except OSError as e:
            if e.errno == errno.EADDRNOTAVAIL:
                raise ViewerUnavailable(f"--view-host {host}: not an address of this machine") from None
            raise ViewerUnavailable(f"{option} {port}: cannot listen on {host}:{port} "
                                    f"({e.strerror or e}); choose another port with {option} N") from None
        return s.getsockname()[1]


def _wait_listening(proc: subprocess.Popen, host: str, port: int, log, what: str) -> None:
    """Wait until `proc` accepts connections on host:port; ViewerUnavailable (with the last line of its
    output) if it exits first or does not listen within START_TIMEOUT."""
    connect_host = LOCALHOST if host in ("0.0.0.0", "") else ("::1" if host == "::" else host)
    deadline = time.monotonic() + START_TIMEOUT
    while time.monotonic() < deadline:
        if proc.poll() is not None:
            raise _exit_reason(proc, log, what)
        try:
            with socket.create_connection((connect_host, port), timeout=0.5):
                return
        except OSError:
            time.sleep(0.1)
    stop_process(proc)
    raise ViewerUnavailable(f"{what} did not listen on {host}:{port} within {START_TIMEOUT:.0f} s")


def _exit_reason(proc: subprocess.Popen, log, what: str) -> ViewerUnavailable:
    """The last line of the process' output, without terminal colour codes."""
    log.seek(0)
    lines = [ln.strip() for ln in log.read().decode("utf-8", "replace").splitlines() if ln.strip()]
    last = ": " + re.sub(r"\x1b\[[0-9;]*m", "", lines[-1]) if lines else ""
    return ViewerUnavailable(f"{what} exited with status {proc.returncode} before it could be used{last}")


def _wait_alive(proc: subprocess.Popen, seconds: float, log, what: str) -> None:
    """ViewerUnavailable if `proc` exits within `seconds` (e.g. a native viewer whose window cannot be
    created: it listens first, then fails on the graphics driver)."""
    with contextlib.suppress(subprocess.TimeoutExpired):
        proc.wait(seconds)
    if proc.returncode is not None:
        raise _exit_reason(proc, log, what)


def _start(cmd: list[str], *, detach: bool) -> tuple[subprocess.Popen, Any]:
    """Start the viewer binary, its output in a temporary file.  detach: it outlives this process; else
    it gets the parent-death signal (Linux), so a killed `teleop` leaves no server behind."""
    log = tempfile.TemporaryFile()
    parent_death_signal()  # looked up here, not in the forked child
    env = {**os.environ, "RERUN_ANALYTICS": os.environ.get("RERUN_ANALYTICS", "0")}
    proc = subprocess.Popen(cmd, stdin=subprocess.DEVNULL, stdout=log, stderr=subprocess.STDOUT, env=env,
                            start_new_session=True,
                            preexec_fn=die_with_parent if os.name == "posix" and not detach else None)
    return proc, log


def stop_process(proc: subprocess.Popen | None, timeout: float = 5.0) -> None:
    """Terminate a started viewer server (its whole process group) and reap it."""
    if proc is None or proc.poll() is not None:
        return

    def kill(sig) -> None:
        with contextlib.suppress(ProcessLookupError, PermissionError):
            if hasattr(os, "killpg"):
                os.killpg(proc.pid, sig)
            else:  # Windows: no process groups to signal
                proc.kill()

    kill(signal.SIGTERM)
    try:
        proc.wait(timeout)
    except subprocess.TimeoutExpired:
        kill(getattr(signal, "SIGKILL", signal.SIGTERM))
        proc.wait(timeout)


class LiveView:
    """Streams chunks of a run to a viewer (or any sinks of `rec`); never raises into the simulation."""

    def __init__(self, rec: rr.RecordingStream, scn=None) -> None:
        self.rec = rec
        self.scn = scn
        self.url: str | None = None  # mode "web": the viewer's address, where it listens, its server
        self.listen: str | None = None
        self.server: subprocess.Popen | None = None
        self.chunks = 0
        self.failed: str | None = None
        self._first: Trajectory | None = None
        self._fmax = 0.0  # N, the largest contact force streamed so far

    @classmethod
    def open(cls, mode: str, scn=None, *, host: str = LOCALHOST, web_port: int = WEB_PORT,
             grpc_port: int = GRPC_PORT, open_browser: bool = True) -> LiveView:
        """A live view on a spawned native viewer (mode "native", free local port) or a web viewer served
        on host:web_port with the data on host:grpc_port (port 0: a free one; `url` to open, stopped by
        `close()`).  Raises ViewerUnavailable (one line) when it cannot be opened."""
        if mode not in VIEW_MODES:
            raise ValueError(f"view mode {mode!r}: expected one of {VIEW_MODES}")
        exe = rerun_executable()
        if mode == "native" and not has_display():
            raise ViewerUnavailable("--view: no display to open the Rerun viewer in (DISPLAY and "
                                    "WAYLAND_DISPLAY are unset); use --view web to watch in a browser, or "
                                    "open the run's run.rrd later with 'rerun FILE'")
        if exe is None:
            raise ViewerUnavailable("--view: the Rerun viewer binary was not found (rerun-sdk's rerun_cli, "
                                    "or 'rerun' on PATH); install rerun-sdk, or run without --view")
        rec = rr.RecordingStream(record.APP_ID)
        view = cls(rec, scn)
        if mode == "native":
            port = _check_free(LOCALHOST, 0, "--grpc-port")
            proc, log = _start([exe, "--bind", LOCALHOST, "--port", str(port), "--expect-data-soon"],
                               detach=True)
            try:
                _wait_listening(proc, LOCALHOST, port, log, "the Rerun viewer")
                # it listens before it creates its window, which can still fail (graphics driver)
                _wait_alive(proc, NATIVE_SETTLE, log, "the Rerun viewer")
            except ViewerUnavailable as e:
                raise ViewerUnavailable(f"--view: {e}; use --view web to watch in a browser") from None
            rec.connect_grpc(f"rerun+http://{LOCALHOST}:{port}/proxy")
            return view
        web_port = _check_free(host, web_port, "--web-port")
        grpc_port = _check_free(host, grpc_port, "--grpc-port")
        proc, log = _start([exe, "--serve-web", "--bind", host, "--port", str(grpc_port),
                            "--web-viewer-port", str(web_port)], detach=False)
        view.server = proc
        try:
            _wait_listening(proc, host, grpc_port, log, "the Rerun web viewer server")
            _wait_listening(proc, host, web_port, log, "the Rerun web viewer server")
        except ViewerUnavailable:
            stop_process(proc)
            raise
        shown = LOCALHOST if host in ("0.0.0.0", "") else ("[::1]" if host == "::" else
                                                             (f"[{host}]" if ":" in host else host))
        data = f"rerun+http://{shown}:{grpc_port}/proxy"
        rec.connect_grpc(data)
        view.url = f"http://{shown}:{web_port}/?url={urllib.parse.quote(data, safe='')}"
        view.listen = f"{host}:{web_port} (viewer) and {host}:{grpc_port} (data)"
        if open_browser and has_display():
            with contextlib.suppress(Exception):
                webbrowser.open(view.url)
        return view

    @classmethod
    def to_file(cls, path: str | Path, scn=None) -> LiveView:
        """A live view whose stream goes to a file (what a viewer would receive; for tests)."""
        rec = rr.RecordingStream(record.APP_ID)
        rec.save(path)
        return cls(rec, scn)

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
            if geometry.has_interaction(part):  # arrows scaled by the largest force streamed so far
                self._fmax = max(self._fmax, record_contact.max_contact_force(part))
                record_contact.log_contacts(self.rec, part, scene.TIMELINE, mb,
                                            record_contact.arrow_scale(part, self._fmax))
            self.chunks += 1
        except Exception as e:  # noqa: BLE001 - the viewer must never stop a run
            self.failed = f"{type(e).__name__}: {e}"
            warnings.warn(f"live view stopped: {self.failed}", stacklevel=2)

    def _start(self, part: Trajectory) -> None:
        if self.scn is not None:
            part.meta["environment"] = [dataclasses.asdict(o) for o in self.scn.environment.objects]
        framing = self._with_desired_path(part)
        self.rec.send_blueprint(scene.build_blueprint(framing))
        record.log_static(self.rec, framing, geometry.world_base(part.meta, "master_base"),
                           geometry.world_base(part.meta, "slave_base"))
        self.rec.log("status", rr.TextDocument("# Run status\n\n* status: **running**\n",
                                               media_type=rr.MediaType.MARKDOWN), static=True)

    def _with_desired_path(self, part: Trajectory) -> Trajectory:
        """`part` extended by the scenario's desired path over the run (framing, static desired path),
        the other rows repeating the last state."""
        if self.scn is None:
            return part
        from harness.loop.common import desired_at

        period = 2.0 * np.pi / max(abs(float(self.scn.trajectory.omega)), 1e-9)
        t = np.linspace(0.0, min(float(self.scn.duration), period), DESIRED_PATH_POINTS)
        xd = np.array([desired_at(self.scn, ti)[0] for ti in t])
        idx = np.concatenate([np.arange(len(part)), np.full(len(t), len(part) - 1)])
        fields = {f.name: None if getattr(part, f.name) is None else getattr(part, f.name)[idx]
                  for f in dataclasses.fields(Trajectory) if f.name not in ("status", "message", "meta")}
        fields["xd"] = np.concatenate([part.xd, xd])
        return Trajectory(**fields, status="running", message="", meta=dict(part.meta))

    def finish(self, traj: Trajectory) -> None:
        """After the run: final status text and desired path (static), and flush to the viewer."""
        if self._first is None or self.failed:
            return
        try:
            mb, sb = (geometry.world_base(traj.meta, key) for key in ("master_base", "slave_base"))
            record.log_static(self.rec, traj, mb, sb)
            self.rec.flush(timeout_sec=FLUSH_TIMEOUT)
        except Exception as e:  # noqa: BLE001
            self.failed = f"{type(e).__name__}: {e}"
            warnings.warn(f"live view stopped: {self.failed}", stacklevel=2)

    def close(self) -> None:
        try:
            with contextlib.suppress(Exception):
                self.rec.flush(timeout_sec=FLUSH_TIMEOUT)
            self.rec.disconnect()
        finally:
            stop_process(self.server)


def open_recording(path: str | Path, mode: str = "native") -> list[str]:
    """Command that opens a recording in a viewer (`rerun FILE` / `rerun --web-viewer FILE`, local only)."""
    exe = rerun_executable() or "rerun"
    return [exe, *(["--web-viewer", "--bind", LOCALHOST] if mode == "web" else []), str(path)]


def spawn_recording_viewer(path: str | Path, settle: float = 2.0) -> list[str]:
    """Open a recording in a native viewer that outlives this process; returns its command.
    ViewerUnavailable (one line) without a display or binary, or if the viewer exits within `settle` s."""
    if not has_display():
        raise ViewerUnavailable(f"no display to open the Rerun viewer in (DISPLAY and WAYLAND_DISPLAY are "
                                f"unset); view it in a browser with: {' '.join(open_recording(path, 'web'))}")
    if rerun_executable() is None:
        raise ViewerUnavailable("the Rerun viewer binary was not found (rerun-sdk's rerun_cli, or 'rerun' "
                                "on PATH)")
    cmd = open_recording(path)
    proc, log = _start(cmd, detach=True)
    _wait_alive(proc, settle, log, "the Rerun viewer")
    return cmd
