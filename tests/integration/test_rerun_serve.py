"""A demo served live (``teleop demo --rerun serve``) watched by a second process: headless Chromium on the web
viewer the slave serves, and the desktop viewer of ``teleop view`` (under a virtual X server) on both sides'
gRPC streams. Each picture must show the sheath route in the tension colour map's colours, and the desktop one
no notification (the viewer's warnings about its host stay in its log).

Deadlines only bound how long a test waits for a condition (the ports listening, the stream flowing, the
colours drawn); nothing passes or fails on how fast it happened.
"""
from __future__ import annotations

import io
import shutil
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pytest

from teleop.rerun.joints import BLUE, ORANGE
from teleop.rerun.layout import tension_colors
from teleop.rerun.serve import session_streams, web_url
from teleop.session.transport import free_tcp_port
from tests.integration.chromium import HeadlessChromium, chromium_executable
from tests.integration.processes import wait_for

ROOT = Path(__file__).resolve().parents[2]
Image = pytest.importorskip("PIL.Image", reason="pillow reads the screenshots")


def _served_config(tmp_path: Path) -> Path:
    """configs/sim.yaml served on free ports, recordings under tmp_path."""
    ports = [free_tcp_port() for _ in range(4)]
    text = (ROOT / "configs" / "sim.yaml").read_text(encoding="utf-8").replace("dir: runs", f"dir: {tmp_path}/runs")
    text += ("  rerun_serve:\n" + "".join(f"    {k}: {p}\n" for k, p in zip(
        ("slave_port", "master_port", "slave_web_port", "master_web_port"), ports, strict=True)))
    (tmp_path / "calibration").mkdir()
    text += f"calibration:\n  dir: {tmp_path}/calibration\n"
    # no SCHED_FIFO loops: on a small machine they leave the servers and the viewers too little CPU to connect
    text = text.replace("\nmaster:\n", "\nmaster:\n  realtime_priority: 0\n") + "slave:\n  realtime_priority: 0\n"
    path = tmp_path / "served.yaml"
    path.write_text(text, encoding="utf-8")
    return path


def _listening(port: int) -> bool:
    import socket
    with socket.socket() as s:
        s.settimeout(0.2)
        return s.connect_ex(("127.0.0.1", port)) == 0


def tension_pixels(png: bytes) -> int:
    """Pixels of ``png`` in the colours of the tension colour map (0-25 N, blue to red; saturated colours that
    the viewer's grey theme and its selection blue do not use)."""
    rgb = np.asarray(Image.open(io.BytesIO(png)).convert("RGB"), dtype=np.int16).reshape(-1, 3)
    palette = tension_colors(np.linspace(0.0, 25.0, 80))[:, :3].astype(np.int16)
    ui = np.array([ORANGE[:3], BLUE[:3], (52, 129, 192)], dtype=np.int16)     # the series' colours, a lane's blue
    palette = palette[np.abs(palette[:, None, :] - ui[None]).max(axis=2).min(axis=1) > 40]
    rgb = rgb[(rgb.max(axis=1) - rgb.min(axis=1)) > 80]          # saturated pixels only
    near = np.zeros(len(rgb), dtype=bool)
    for c in palette:
        near |= np.abs(rgb - c).max(axis=1) <= 12
    return int(near.sum())


def _start_demo(cfg: Path, tmp: Path) -> subprocess.Popen:
    log = open(tmp / "demo.log", "w")
    return subprocess.Popen([sys.executable, "-m", "live.cli", "demo", "--config", str(cfg), "--rerun", "serve",
                             "--run-dir", str(tmp / "run")], stdout=log, stderr=subprocess.STDOUT)


def _poll_screenshots(take, deadline_s: float) -> tuple[bytes, int]:
    """Screenshots from ``take()`` until one shows the tension colours (or the deadline): (last png, its count)."""
    end, png, count = time.monotonic() + deadline_s, b"", 0
    while time.monotonic() < end:
        png = take()
        count = tension_pixels(png)
        if count > 300:
            break
        time.sleep(1.0)
    return png, count


@pytest.mark.integration
def test_a_served_demo_is_watched_in_headless_chromium_and_in_the_desktop_viewer(tmp_path):
    """While the demo runs (its sides serve for about 20 s), the desktop viewer of ``teleop view`` and headless
    Chromium on the slave's web viewer open both streams; each picture shows the sheath in the tension colours."""
    exe = chromium_executable()
    if exe is None:
        pytest.skip("Chromium is not installed (Debian: apt-get install chromium): the web viewer is not tested")
    if shutil.which("xvfb-run") is None:
        pytest.skip("xvfb-run is not installed (Debian: apt-get install xvfb mesa-vulkan-drivers)")
    from teleop.config.load import load_config
    cfg = _served_config(tmp_path)
    serve = load_config(cfg).recording.rerun_serve
    browser = HeadlessChromium(exe)                 # started first: the page loads while the sides calibrate
    demo = _start_demo(cfg, tmp_path)
    desktop, out = None, tmp_path / "desktop.png"
    try:
        wait_for(lambda: all(_listening(p) for p in (serve.slave_port, serve.master_port, serve.slave_web_port)),
                 120, "the sides' gRPC servers and the slave's web viewer")
        desktop = subprocess.Popen(["xvfb-run", "-a", "-s", "-screen 0 1600x1000x24", sys.executable, "-m",
                                    "live.cli", "view", "--config", str(cfg), "--window-size", "1600x1000",
                                    "--screenshot-to", str(out)], stdout=subprocess.DEVNULL,
                                   stderr=open(tmp_path / "view.log", "w"))
        browser.open(web_url("127.0.0.1", serve.slave_web_port, session_streams(load_config(cfg))))
        png, count = _poll_screenshots(browser.screenshot, 60)
        title = browser.call("Runtime.evaluate", page=True, expression="document.title")["result"]["value"]
        assert desktop.wait(120) == 0 and out.is_file(), (tmp_path / "view.log").read_text()[-2000:]
    finally:
        browser.close()
        for p in (desktop, demo):
            if p is not None and p.poll() is None:
                p.terminate()
                p.wait(60)
    (tmp_path / "web.png").write_bytes(png)
    rgb = np.asarray(Image.open(io.BytesIO(png)).convert("RGB"))
    assert title == "Rerun Viewer"
    assert rgb.shape[:2] == (1000, 1600) and rgb.std() > 10, "a blank page"
    assert count > 300, f"no sheath in the tension colours in the browser ({count} pixels; {tmp_path / 'web.png'})"
    shot = out.read_bytes()
    rgb = np.asarray(Image.open(io.BytesIO(shot)).convert("RGB"), dtype=np.int16)
    assert rgb.shape[:2] == (2000, 3200)          # 1600x1000 points at the screenshotter's 2 pixels per point
    assert tension_pixels(shot) > 300, f"no sheath in the tension colours on the desktop ({out})"
    corner = rgb[:60, -700:].reshape(-1, 3)       # the top bar's notification bell: a red or orange dot when warned
    dot = (corner[:, 0] > 200) & (corner[:, 1] < 170) & (corner[:, 2] < 80)
    assert dot.sum() == 0, f"a notification in the desktop viewer ({out})"
