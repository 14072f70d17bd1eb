"""Headless Chromium driven over the DevTools protocol on a pipe (``--remote-debugging-pipe``: JSON messages
separated by NUL on file descriptors 3 and 4), for the tests that look at a page: navigate, screenshot, close.

WebGL renders on SwiftShader, Chromium's CPU renderer (``--use-angle=swiftshader``): no GPU is needed.
"""
from __future__ import annotations

import base64
import json
import os
import shutil
import subprocess

__all__ = ["chromium_executable", "HeadlessChromium"]


def chromium_executable() -> str | None:
    """The Chromium (Debian's ``chromium``) or Chrome found on PATH, or None."""
    for name in ("chromium", "chromium-browser", "google-chrome"):
        path = shutil.which(name)
        if path:
            return path
    return None


class HeadlessChromium:
    """One headless browser with one page of ``width`` x ``height`` CSS pixels at 1 device pixel each."""

    def __init__(self, executable: str, width: int = 1600, height: int = 1000):
        to_browser, self._w = os.pipe()
        self._r, from_browser = os.pipe()

        def on_fds_3_and_4() -> None:          # in the child: the protocol's pipes where Chromium expects them
            a, b = os.dup(to_browser), os.dup(from_browser)
            os.dup2(a, 3)
            os.dup2(b, 4)

        self.proc = subprocess.Popen(
            [executable, "--headless=new", "--no-sandbox", "--remote-debugging-pipe", "--use-angle=swiftshader",
             "--enable-unsafe-swiftshader", "--ignore-gpu-blocklist", "--no-first-run",
             f"--window-size={width},{height}",
             "about:blank"], close_fds=False, preexec_fn=on_fds_3_and_4, stdin=subprocess.DEVNULL,
            stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
        os.close(to_browser)
        os.close(from_browser)
        self._id, self._buf = 0, b""
        self._session = ""
        self._size = (width, height)

    def call(self, method: str, page: bool = False, **params) -> dict:
        """Send one command (to the page with ``page``) and return its result; RuntimeError on a protocol error,
        EOFError when the browser has gone."""
        self._id += 1
        msg: dict = {"id": self._id, "method": method, "params": params}
        if page:
            msg["sessionId"] = self._session
        os.write(self._w, json.dumps(msg).encode() + b"\0")
        while True:
            while b"\0" not in self._buf:
                chunk = os.read(self._r, 1 << 20)
                if not chunk:
                    raise EOFError(f"chromium ended before answering {method}")
                self._buf += chunk
            raw, self._buf = self._buf.split(b"\0", 1)
            answer = json.loads(raw)
            if answer.get("id") == self._id:
                if "error" in answer:
                    raise RuntimeError(f"{method}: {answer['error']}")
                return answer["result"]

    def open(self, url: str) -> None:
        """A page on ``url`` (a new target, so that no navigation swaps its process under the session)."""
        target = self.call("Target.createTarget", url=url, width=self._size[0], height=self._size[1])["targetId"]
        self._session = self.call("Target.attachToTarget", targetId=target, flatten=True)["sessionId"]
        self.call("Emulation.setDeviceMetricsOverride", page=True, width=self._size[0], height=self._size[1],
                  deviceScaleFactor=1, mobile=False)

    def screenshot(self) -> bytes:
        """The page as PNG bytes."""
        return base64.b64decode(self.call("Page.captureScreenshot", page=True, format="png")["data"])

    def close(self) -> None:
        self.proc.kill()
        self.proc.wait()
        os.close(self._w)
        os.close(self._r)
