"""Live viewing of a run in Rerun (`LiveView`: each chunk of steps with the entities and blueprint of the
`.rrd` file, `harness.output.record`), and opening recordings.  Modes: `teleop run --help`."""

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
from harness.output import geometry, record, scene

DESIRED_PATH_POINTS = 400
LOCALHOST = "127.0.0.1"
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
    """Wait until `proc` accepts connections on host:port; ViewerUnavailable if it exits first or does not
    listen within START_TIMEOUT."""
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
    """ViewerUnavailable if `proc` exits within `seconds` (e.g. a native viewer without a usable GPU)."""
    with contextlib.suppress(subprocess.TimeoutExpired):
        proc.wait(seconds)
    if proc.returncode is not None:
        raise _exit_reason(proc, log, what)


def _start(cmd: list[str], *, detach: bool) -> tuple[subprocess.Popen, Any]:
    """Start the viewer binary, its output in a temporary file.  detach: it outlives this process; else it
    dies with it (parent-death signal on Linux)."""
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
        self.url = self.listen = None  # mode "web": the viewer's address, where it listens, its server
        self.server: subprocess.Popen | None = None
        self.chunks = 0
        self.failed: str | None = None
        self._fmax = 0.0  # N, the largest contact force streamed so far

    @classmethod
    def open(cls, mode: str, scn, *, host: str, web_port: int, grpc_port: int) -> LiveView:
        """A live view on a spawned native viewer ("native", free local port) or a web viewer served on
        host:web_port, the data on host:grpc_port (0: a free port; `url`; stopped by `close()`).  Raises
        ViewerUnavailable (one line) when it cannot be opened."""
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
        if has_display():
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
            if not self.chunks:
                self._start(part)
            if geometry.has_interaction(part):  # arrows scaled by the largest force streamed so far
                self._fmax = max(self._fmax, record.max_contact_force(part))
            record.log_steps(self.rec, part, 500, 1, self._fmax)
            self.chunks += 1
        except Exception as e:  # noqa: BLE001 - the viewer must never stop a run
            self.failed = f"{type(e).__name__}: {e}"
            warnings.warn(f"live view stopped: {self.failed}", stacklevel=2)

    def _start(self, part: Trajectory) -> None:
        """Blueprint and static content, framed by `part` extended by the scenario's desired path over the
        run (the other rows repeating the last state)."""
        framing = part
        if self.scn is not None:
            from harness.loop.common import desired_at

            period = 2.0 * np.pi / max(abs(float(self.scn.trajectory.omega)), 1e-9)
            t = np.linspace(0.0, min(float(self.scn.duration), period), DESIRED_PATH_POINTS)
            xd = np.array([desired_at(self.scn, ti)[0] for ti in t])
            idx = np.concatenate([np.arange(len(part)), np.full(len(t), len(part) - 1)])
            fields = {f.name: None if getattr(part, f.name) is None else getattr(part, f.name)[idx]
                      for f in dataclasses.fields(Trajectory) if f.name not in ("status", "message", "meta")}
            fields["xd"] = np.concatenate([part.xd, xd])
            framing = Trajectory(**fields, status="running", message="", meta=dict(part.meta))
        self.rec.send_blueprint(scene.build_blueprint(framing))
        record.log_static(self.rec, framing)
        self.rec.log("status", rr.TextDocument("# Run status\n\n* status: **running**\n",
                                               media_type=rr.MediaType.MARKDOWN), static=True)

    def finish(self, traj: Trajectory) -> None:
        """After the run: final status text and desired path (static), and flush to the viewer."""
        if not self.chunks or self.failed:
            return
        try:
            record.log_static(self.rec, traj)
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


def spawn_recording_viewer(path: str | Path, settle: float = 2.0) -> list[str]:
    """Open a recording in a native viewer that outlives this process; returns its command.
    ViewerUnavailable (one line) without a display or binary, or if the viewer exits within `settle` s."""
    exe = rerun_executable()
    if not has_display():
        raise ViewerUnavailable(f"no display to open the Rerun viewer in (DISPLAY and WAYLAND_DISPLAY are "
                                f"unset); view it in a browser with: {exe or 'rerun'} --web-viewer --bind "
                                f"{LOCALHOST} {path}")
    if exe is None:
        raise ViewerUnavailable("the Rerun viewer binary was not found (rerun-sdk's rerun_cli, or 'rerun' "
                                "on PATH)")
    proc, log = _start([exe, str(path)], detach=True)
    _wait_alive(proc, settle, log, "the Rerun viewer")
    return [exe, str(path)]
