"""A side's live Rerun stream served to viewers elsewhere (``recording.rerun: serve``), and how a viewer opens it.

Each side's logging process serves its recording over gRPC (Rerun's ``GrpcServerSink``) on
``recording.rerun_serve.bind`` and the side's port (``slave_port``, ``master_port``), keeping the latest
``memory_limit`` bytes of the stream for viewers that connect late (static data is always kept), and runs the
web viewer (``rerun --serve-web``, HTTP, static pages only) on the side's web port, bound to the same address.
A desktop viewer opens ``rerun+http://<host>:<port>/proxy`` of both sides (:func:`grpc_url`, ``teleop view``); a
browser opens the web viewer's page with both sides' gRPC addresses in its query (:func:`web_url`) and then
reaches those gRPC ports itself.

:func:`viewer_env` is the environment a viewer started here runs in: the viewer's warnings about its host (a
container, a software renderer, the C locale), which it shows as notifications over the view, are kept in its
log.
"""
from __future__ import annotations

import os
import subprocess
import sys
import tempfile
from dataclasses import dataclass
from pathlib import Path
from typing import Any
from urllib.parse import quote

__all__ = ["ServeSpec", "serve_spec", "grpc_url", "web_url", "rerun_executable", "start_web_viewer", "viewer_env",
           "session_streams", "viewer_command", "QUIET_TARGETS"]

#: Log targets of the viewer whose warnings describe its host, not the session (shown as notifications otherwise):
#: the container check, the software renderer (Mesa llvmpipe, a headless machine), winit's X11 display checks.
QUIET_TARGETS = ("re_viewer::native", "re_renderer::context", "egui_wgpu", "winit", "egui_system_font_provider")


@dataclass(frozen=True)
class ServeSpec:
    """Where one side serves: ``bind`` (IP address), gRPC ``port``, ``web_port`` (0: no web viewer), the server's
    ``memory_limit`` [B]."""

    bind: str
    port: int
    web_port: int
    memory_limit: int

    @property
    def grpc_url(self) -> str:
        """The stream's URL on the bound address (``rerun+http://127.0.0.1:9876/proxy``)."""
        return grpc_url(self.bind, self.port)


def serve_spec(cfg: Any, side: str) -> ServeSpec:
    """The :class:`ServeSpec` of ``side`` (``slave`` or ``master``) from ``cfg.recording.rerun_serve``.

    Raises
    ------
    ValueError
        ``side`` is neither.
    """
    if side not in ("slave", "master"):
        raise ValueError(f"serve_spec: side {side!r} is neither 'slave' nor 'master'")
    s = cfg.recording.rerun_serve
    return ServeSpec(str(s.bind), int(getattr(s, f"{side}_port")), int(getattr(s, f"{side}_web_port")),
                     int(s.memory_limit))


def _host(host: str) -> str:
    """``host`` as it goes into a URL: an IPv6 address in brackets; the any-address as loopback."""
    if host in ("0.0.0.0", "::"):
        host = "127.0.0.1"
    return f"[{host}]" if ":" in host and not host.startswith("[") else host


def grpc_url(host: str, port: int) -> str:
    """The gRPC URL a viewer opens: ``rerun+http://<host>:<port>/proxy``."""
    return f"rerun+http://{_host(host)}:{int(port)}/proxy"


def web_url(host: str, web_port: int, streams: list[str]) -> str:
    """The web viewer's page at ``host``:``web_port`` opening every gRPC URL of ``streams``."""
    query = "&".join(f"url={quote(u, safe='')}" for u in streams)
    return f"http://{_host(host)}:{int(web_port)}/?{query}"


def rerun_executable() -> str:
    """The ``rerun`` viewer binary of the installed rerun-sdk (``rerun_cli/rerun``: the binary itself, not the
    console script that runs it as a child, so that ending the process ends the viewer), else ``rerun`` beside
    this interpreter or on PATH."""
    try:
        import rerun_cli
        binary = Path(rerun_cli.__file__).with_name("rerun")
        if binary.is_file():
            return str(binary)
    except ImportError:
        pass
    beside = Path(sys.executable).with_name("rerun")
    return str(beside) if beside.is_file() else "rerun"


def viewer_env(base: dict[str, str] | None = None) -> dict[str, str]:
    """The environment for a viewer started from here: ``base`` (default ``os.environ``) with ``RUST_LOG`` keeping
    the warnings of :data:`QUIET_TARGETS` out of the view, a UTF-8 locale where it is C or unset and a private
    ``XDG_RUNTIME_DIR`` where none is set."""
    env = dict(os.environ if base is None else base)
    env.setdefault("RUST_LOG", ",".join(["warn", *(f"{t}=error" for t in QUIET_TARGETS)]))
    if env.get("LC_ALL", env.get("LANG", "C")) in ("C", "POSIX", ""):
        env["LC_ALL"] = env["LANG"] = "C.UTF-8"
    if not env.get("XDG_RUNTIME_DIR"):
        env["XDG_RUNTIME_DIR"] = tempfile.mkdtemp(prefix="tsm-teleop-xdg-")
    return env


def start_web_viewer(spec: ServeSpec, streams: list[str] | None = None) -> subprocess.Popen | None:
    """The web viewer of ``spec`` (``rerun --serve-web``: its pages on ``spec.bind``:``spec.web_port``, opening
    ``streams``, default the side's own gRPC URL), as a child process; None when ``web_port`` is 0.

    Raises
    ------
    OSError
        The ``rerun`` executable cannot be started.
    """
    if not spec.web_port:
        return None
    cmd = [rerun_executable(), "--serve-web", "--bind", spec.bind, "--web-viewer-port", str(spec.web_port),
           *(streams or [spec.grpc_url])]
    return subprocess.Popen(cmd, stdin=subprocess.DEVNULL, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL,
                            env=viewer_env(), close_fds=True, preexec_fn=_end_with_parent)


def _end_with_parent() -> None:
    """In the web viewer's process before it starts (Linux): SIGTERM when the logging process that started it
    ends, however it ends (a killed side leaves no web server behind)."""
    if sys.platform.startswith("linux"):
        import ctypes
        import signal
        ctypes.CDLL(None).prctl(1, signal.SIGTERM)       # PR_SET_PDEATHSIG


def session_streams(cfg: Any, slave_host: str | None = None, master_host: str | None = None) -> list[str]:
    """The gRPC URLs of a served session's two sides (slave, master) as ``cfg.recording.rerun_serve`` places them;
    each host defaults to the configured bind address (loopback: this machine)."""
    s = cfg.recording.rerun_serve
    return [grpc_url(slave_host or s.bind, s.slave_port), grpc_url(master_host or s.bind, s.master_port)]


def viewer_command(streams: list[str], screenshot: str | None = None, window_size: str | None = None) -> list[str]:
    """The desktop viewer's command line opening ``streams``; with ``screenshot`` it saves a PNG of the view and
    quits (at 2 pixels per point: ``window_size`` 1600x1000 gives 3200x2000, the viewer's screenshotter renders
    as on a HiDPI display)."""
    cmd = [rerun_executable(), *streams]
    if window_size:
        cmd += ["--window-size", window_size]
    if screenshot:
        cmd += ["--screenshot-to", screenshot]
    return cmd
