"""The recording as a person sees it: a short MuJoCo run's `.rrd` served to Rerun's web viewer (shipped in
the rerun-sdk wheel), opened in headless Chromium with software WebGL, screenshot, and checked from pixels:

* the 3-D view shows the master's and the slave's colours, both whole (their pixels do not touch the view's
  edges), i.e. the blueprint's eye frames both arms;
* the 2-D "Tip traces" view shows both tip traces as more than a point (pixel extents), inside the view
  with a margin, i.e. the blueprint's visual bounds frame the traces.

The views are located on the screenshot by their solid backgrounds (`harness.output.scene.BG_3D`, `BG_2D`).
The screenshot is kept as an artefact: $TELEOP_VIEWER_SCREENSHOT or tests/artifacts/viewer_default_layout.png
(git-ignored; docs/viewer_default_layout.png in the README is a copy of one).  Chromium is driven over the
DevTools protocol on a pipe (--remote-debugging-pipe), so no Python browser package is needed.  Skipped only
when no Chromium/Chrome binary is found (CI installs the system package in .ci/run).
"""

from __future__ import annotations

import base64
import http.server
import io
import json
import os
import select
import shutil
import signal
import socket
import subprocess
import sys
import threading
import time
import urllib.parse
import urllib.request
from pathlib import Path

import numpy as np
import pytest

from harness.output import record, scene

BROWSERS = ("chromium", "chromium-browser", "google-chrome", "google-chrome-stable")
SIZE = (1600, 1000)  # browser viewport, CSS px (device scale factor 1)
STREAM_TIMEOUT = 150.0  # s until the views must show their content (software WebGL on a loaded machine)
COLOUR_TOL = 24  # max abs RGB difference that counts as "this colour" (anti-aliasing, shading)
MIN_TRACE_EXTENT = 20  # px, each trace's width and height in the trace view
EDGE_MARGIN = 4  # px between content and a view's edge ("whole", "with a margin")
ARTIFACT = Path(os.environ.get("TELEOP_VIEWER_SCREENSHOT")
                or Path(__file__).parent / "artifacts" / "viewer_default_layout.png")


def _browser() -> str | None:
    for name in BROWSERS:
        found = shutil.which(name)
        if found:
            return found
    return None


def _rerun_cli() -> str:
    exe = Path(sys.executable).with_name("rerun")
    return str(exe) if exe.exists() else (shutil.which("rerun") or "rerun")


def _free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


class _DevTools:
    """Minimal Chrome DevTools protocol client over --remote-debugging-pipe (fd 3: commands in, fd 4: out;
    messages are JSON terminated by NUL)."""

    def __init__(self, exe: str, profile: Path, log: Path) -> None:
        cmd_r, cmd_w = os.pipe()
        res_r, res_w = os.pipe()

        def child_fds() -> None:  # move the pipe ends to fds 3 and 4 (via free fds: they may be 3 or 4)
            a, b = os.dup(cmd_r), os.dup(res_w)
            os.dup2(a, 3)
            os.dup2(b, 4)

        args = [exe, "--headless=new", "--no-sandbox", "--remote-debugging-pipe", "--use-gl=angle",
                "--use-angle=swiftshader", "--enable-unsafe-swiftshader", "--ignore-gpu-blocklist",
                "--hide-scrollbars", "--no-first-run", "--no-default-browser-check", "--disable-extensions",
                "--mute-audio", f"--window-size={SIZE[0]},{SIZE[1]}", f"--user-data-dir={profile}",
                "about:blank"]
        self.log = open(log, "wb")  # noqa: SIM115 - closed in close()
        self.proc = subprocess.Popen(args, pass_fds=(3, 4), preexec_fn=child_fds, stdin=subprocess.DEVNULL,
                                     stdout=self.log, stderr=self.log)
        os.close(cmd_r)
        os.close(res_w)
        self.w, self.r = cmd_w, res_r
        self.buf = b""
        self.next_id = 0

    def call(self, method: str, session: str | None = None, timeout: float = 60.0, **params) -> dict:
        self.next_id += 1
        msg = {"id": self.next_id, "method": method, "params": params}
        if session:
            msg["sessionId"] = session
        os.write(self.w, json.dumps(msg).encode() + b"\0")
        deadline = time.monotonic() + timeout
        while True:
            while b"\0" not in self.buf:
                left = deadline - time.monotonic()
                if left <= 0 or not select.select([self.r], [], [], left)[0]:
                    raise TimeoutError(f"DevTools {method}: no answer in {timeout} s")
                chunk = os.read(self.r, 1 << 20)
                if not chunk:
                    raise RuntimeError(f"the browser closed the DevTools pipe (see {self.log.name})")
                self.buf += chunk
            raw, self.buf = self.buf.split(b"\0", 1)
            reply = json.loads(raw)
            if reply.get("id") == self.next_id:
                if "error" in reply:
                    raise RuntimeError(f"DevTools {method}: {reply['error']}")
                return reply["result"]

    def open_page(self, url: str) -> str:
        target = self.call("Target.createTarget", url=url)["targetId"]
        session = self.call("Target.attachToTarget", targetId=target, flatten=True)["sessionId"]
        self.call("Emulation.setDeviceMetricsOverride", session=session, width=SIZE[0], height=SIZE[1],
                  deviceScaleFactor=1, mobile=False)
        return session

    def screenshot(self, session: str) -> bytes:
        return base64.b64decode(self.call("Page.captureScreenshot", session=session, format="png",
                                          timeout=90.0)["data"])

    def close(self) -> None:
        try:
            self.call("Browser.close", timeout=10.0)
            self.proc.wait(timeout=10)
        except Exception:  # noqa: BLE001 - make sure it is gone below
            pass
        if self.proc.poll() is None:
            self.proc.kill()
            self.proc.wait(timeout=10)
        for fd in (self.w, self.r):
            os.close(fd)
        self.log.close()


# ---------------------------------------------------------------------------------------------
# pixel analysis
# ---------------------------------------------------------------------------------------------
def _decode(png: bytes) -> np.ndarray:
    from PIL import Image

    return np.asarray(Image.open(io.BytesIO(png)).convert("RGB")).astype(np.int16)


def _rect(img: np.ndarray, bg) -> tuple[int, int, int, int] | None:
    """(x0, y0, x1, y1) inclusive bounding box of the pixels of exactly colour `bg` (a view's background)."""
    ys, xs = np.nonzero(np.all(img == np.asarray(bg), axis=-1))
    if len(xs) < 1000:
        return None
    return int(xs.min()), int(ys.min()), int(xs.max()), int(ys.max())


def _colour_box(img: np.ndarray, rect, colour) -> tuple[int, tuple[int, int, int, int] | None]:
    """(pixel count, bounding box in screenshot coordinates) of `colour` inside `rect`."""
    x0, y0, x1, y1 = rect
    sub = img[y0:y1 + 1, x0:x1 + 1]
    ys, xs = np.nonzero(np.abs(sub - np.asarray(colour)).max(axis=-1) <= COLOUR_TOL)
    if not len(xs):
        return 0, None
    return len(xs), (x0 + int(xs.min()), y0 + int(ys.min()), x0 + int(xs.max()), y0 + int(ys.max()))


def _inside(box, rect, margin: int) -> bool:
    return (box[0] - rect[0] >= margin and box[1] - rect[1] >= margin and rect[2] - box[2] >= margin
            and rect[3] - box[3] >= margin)


def analyse(img: np.ndarray) -> tuple[dict, list[str]]:
    """Measurements of a screenshot of the default layout and the list of failed checks."""
    facts: dict = {}
    bad: list[str] = []
    r3, r2 = _rect(img, scene.BG_3D), _rect(img, scene.BG_2D)
    facts["view_3d"], facts["view_traces"] = r3, r2
    if r3 is None or r2 is None:
        return facts, ["the 3-D and trace views (located by their backgrounds) are not both on screen"]
    for name, colour in (("master", scene.C_MASTER), ("slave", scene.C_SLAVE)):
        n, box = _colour_box(img, r3, colour)
        facts[f"3d_{name}"] = (n, box)
        if n < 200:
            bad.append(f"3-D view: {n} px of the {name}'s colour {colour} (expected >= 200)")
        elif not _inside(box, r3, EDGE_MARGIN):
            bad.append(f"3-D view: the {name} is cut off (its pixels {box} reach the view's edge {r3})")
    for name, colour in (("master", scene.C_MASTER), ("slave", scene.C_SLAVE)):
        n, box = _colour_box(img, r2, colour)
        w, h = (box[2] - box[0] + 1, box[3] - box[1] + 1) if box else (0, 0)
        facts[f"trace_{name}"] = (n, box, (w, h))
        if w <= MIN_TRACE_EXTENT or h <= MIN_TRACE_EXTENT:
            bad.append(f"trace view: the {name}'s trace spans {w} x {h} px (expected > {MIN_TRACE_EXTENT} "
                       "each)")
        elif not _inside(box, r2, EDGE_MARGIN):
            bad.append(f"trace view: the {name}'s trace {box} reaches the view's edge {r2} (no margin)")
    return facts, bad


# ---------------------------------------------------------------------------------------------
@pytest.fixture(scope="module")
def short_run_rrd(tmp_path_factory) -> Path:
    from harness.config.scenario import Scenario
    from harness.loop.mujoco_loop import simulate_mujoco

    traj = simulate_mujoco(Scenario(duration=1.0))
    assert traj.status == "ok"
    return record.write_recording(traj, tmp_path_factory.mktemp("viewer") / "run.rrd")


class _FileServer:
    """HTTP server (thread) for the files of one folder, with the CORS header the web viewer needs to
    fetch them from another port."""

    def __init__(self, folder: Path) -> None:
        class Handler(http.server.SimpleHTTPRequestHandler):
            def __init__(self, *args, **kwargs):
                super().__init__(*args, directory=str(folder), **kwargs)

            def end_headers(self):
                self.send_header("Access-Control-Allow-Origin", "*")
                super().end_headers()

            def log_message(self, *args):
                pass

        self.server = http.server.ThreadingHTTPServer(("127.0.0.1", 0), Handler)
        self.url = f"http://127.0.0.1:{self.server.server_address[1]}"
        self.thread = threading.Thread(target=self.server.serve_forever, daemon=True)
        self.thread.start()

    def close(self) -> None:
        self.server.shutdown()
        self.server.server_close()
        self.thread.join(timeout=10)


def _wait_http(url: str, proc: subprocess.Popen, timeout: float = 30.0) -> None:
    deadline = time.monotonic() + timeout
    while time.monotonic() < deadline:
        if proc.poll() is not None:
            raise RuntimeError(f"the rerun web viewer server exited ({proc.returncode})")
        try:
            with urllib.request.urlopen(url, timeout=2):
                return
        except OSError:
            time.sleep(0.2)
    raise TimeoutError(f"{url} did not answer in {timeout} s")


@pytest.mark.slow
def test_default_layout_in_the_web_viewer(short_run_rrd, tmp_path):
    exe = _browser()
    if exe is None:
        pytest.skip(f"no Chromium/Chrome binary found (looked for {', '.join(BROWSERS)} on PATH)")
    t_start = time.monotonic()
    web = _free_port()
    # the web viewer (assets shipped in the rerun-sdk wheel) and, from a second local server, the .rrd
    # file it loads by URL (in one go: faster here than streaming it from the viewer's gRPC proxy)
    viewer = subprocess.Popen(
        [_rerun_cli(), "--serve-web", "--bind", "127.0.0.1", "--web-viewer-port", str(web),
         "--port", str(_free_port())],
        stdin=subprocess.DEVNULL, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL,
        env={**os.environ, "RERUN_ANALYTICS": "0"}, start_new_session=True)  # own group: see finally
    files = _FileServer(short_run_rrd.parent)
    chrome = None
    try:
        _wait_http(f"http://127.0.0.1:{web}/", viewer)
        source = urllib.parse.quote(f"{files.url}/{short_run_rrd.name}", safe="")
        chrome = _DevTools(exe, tmp_path / "profile", tmp_path / "chromium.log")
        session = chrome.open_page(f"http://127.0.0.1:{web}/?url={source}")
        # wait for the stream: until every check passes, or the picture is stable after the views appeared
        deadline = time.monotonic() + STREAM_TIMEOUT
        previous, stable = None, 0
        while True:
            png = chrome.screenshot(session)
            img = _decode(png)
            facts, bad = analyse(img)
            views_up = facts.get("view_3d") is not None and facts.get("view_traces") is not None
            stable = stable + 1 if previous is not None and np.array_equal(img, previous) and views_up else 0
            previous = img
            if os.environ.get("TELEOP_VIEWER_DEBUG"):
                print(f"{time.monotonic() - t_start:6.1f} s: {bad or 'ok'}", flush=True)
            # done when the checks pass on a settled picture (the file loads progressively), or when it
            # settled without passing, or at the deadline
            if (not bad and stable >= 1) or stable >= 2 or time.monotonic() > deadline:
                break
            time.sleep(1.0)
    finally:
        if chrome is not None:
            chrome.close()
        files.close()
        # the `rerun` script runs the viewer binary as a child: stop the whole process group we started
        os.killpg(viewer.pid, signal.SIGTERM)
        viewer.wait(timeout=10)
    ARTIFACT.parent.mkdir(parents=True, exist_ok=True)
    ARTIFACT.write_bytes(png)
    elapsed = time.monotonic() - t_start
    print(f"viewer screenshot {ARTIFACT} after {elapsed:.1f} s: {facts}")
    assert not bad, f"{'; '.join(bad)} (screenshot: {ARTIFACT}; measured: {facts})"


# ---------------------------------------------------------------------------------------------
@pytest.mark.slow
def test_run_view_streams_chunks_while_simulating(tmp_path, monkeypatch):
    """`teleop run --view`: the live stream gets every chunk as the loop produces it (here into a file
    instead of a spawned viewer), with the same series and plant geometry as run.rrd, which is written as
    without --view."""
    from harness.cli import main
    from harness.output import viewer

    opened = []

    def to_file(mode, scn, **kw):
        assert mode == "native"
        opened.append(viewer.LiveView.to_file(tmp_path / "live.rrd", scn))
        return opened[-1]

    monkeypatch.setattr(viewer.LiveView, "open", staticmethod(to_file))
    out = tmp_path / "out"
    assert main(["run", "--duration", "2.5", "--view", "--out", str(out), "--no-progress"]) == 0
    (live,) = opened
    assert live.failed is None and live.chunks >= 2  # streamed during the run, not once at its end
    for entity in ("plots/e2", "plots/e2_plant", "plots/q2"):
        t_live, v_live = record.read_series(tmp_path / "live.rrd", entity)
        t_file, v_file = record.read_series(out / "run.rrd", entity)
        np.testing.assert_array_equal(t_live, t_file)
        np.testing.assert_array_equal(v_live, v_file)
    from rerun.chunk import RrdReader

    reader = RrdReader(tmp_path / "live.rrd")
    assert len(reader.blueprints()) == 1
    rows = {}
    for c in reader.stream().to_chunks():
        if not c.is_static:
            rows[c.entity_path] = rows.get(c.entity_path, 0) + c.num_rows
    assert rows["/world/slave/segments"] == rows["/traces/slave"] == rows["/world/master/arm"] == 2500
