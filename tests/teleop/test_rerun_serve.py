"""Serving the live view (teleop/rerun/serve.py, RerunLogger mode 'serve'): the URLs a viewer opens, the config's
checks, the session timeline's origin, a served stream read back by a second client, and ``teleop view --web``."""
from __future__ import annotations

import socket
import time
from urllib.parse import parse_qs, urlsplit

import pytest

pytest.importorskip("rerun")

from live.cli import main  # noqa: E402
from teleop.config.load import config_from_dict  # noqa: E402
from teleop.errors import ConfigError  # noqa: E402
from teleop.rerun.logger import RerunLogger, session_origin  # noqa: E402
from teleop.rerun.serve import ServeSpec, grpc_url, serve_spec, session_streams, viewer_env, web_url  # noqa: E402
from teleop.session.transport import free_tcp_port  # noqa: E402


def test_urls_name_the_host_port_and_both_streams():
    assert grpc_url("10.0.0.2", 9877) == "rerun+http://10.0.0.2:9877/proxy"
    assert grpc_url("::1", 9877) == "rerun+http://[::1]:9877/proxy"
    assert grpc_url("0.0.0.0", 9877) == "rerun+http://127.0.0.1:9877/proxy"     # the any-address: reach it here
    streams = ["rerun+http://a:1/proxy", "rerun+http://b:2/proxy"]
    url = urlsplit(web_url("a", 9097, streams))
    assert (url.hostname, url.port) == ("a", 9097) and parse_qs(url.query)["url"] == streams


def test_each_side_serves_on_its_own_ports_from_the_config():
    cfg = config_from_dict({"recording": {"rerun_serve": {"slave_port": 1001, "master_port": 1002,
                                                          "slave_web_port": 0, "memory_limit": 5e6}}})
    assert serve_spec(cfg, "slave") == ServeSpec("127.0.0.1", 1001, 0, 5_000_000)
    assert serve_spec(cfg, "master").port == 1002
    assert session_streams(cfg, "h1") == ["rerun+http://h1:1001/proxy", "rerun+http://127.0.0.1:1002/proxy"]


@pytest.mark.parametrize("serve, match", [
    ({"bind": "lab-pc"}, r"recording.rerun_serve.bind: 'lab-pc' is not an IP address"),
    ({"bind": "0.0.0.0"}, r"recording.rerun_serve.bind = 0.0.0.0: the hard bound is 127.0.0.1: .*safety.override"),
    ({"master_port": 9877},
     r"recording.rerun_serve.master_port: port 9877 is already recording.rerun_serve.slave_port"),
    ({"memory_limit": 4e9}, r"recording.rerun_serve.memory_limit = 4e\+09: above the hard bound 1e\+09 B"),
    ({"memory_limit": 10.0}, r"recording.rerun_serve.memory_limit: 10.0 is out of range"),
    ({"slave_port": 0}, r"recording.rerun_serve.slave_port: 0 is out of range"),
])
def test_a_bad_serving_setting_is_one_line_naming_the_key(serve, match):
    with pytest.raises(ConfigError, match=match):
        config_from_dict({"recording": {"rerun_serve": serve}})


def test_another_bind_address_is_a_waiver():
    cfg = config_from_dict({"recording": {"rerun_serve": {"bind": "0.0.0.0"}},
                            "safety": {"override": ["recording.rerun_serve.bind"]}})
    assert cfg.recording.rerun_serve.bind == "0.0.0.0"


def test_the_session_starts_at_the_run_ids_time_stamp():
    assert session_origin("20260102-030405") == time.mktime((2026, 1, 2, 3, 4, 5, 0, 0, -1))
    assert session_origin("20260102-030405-2") == session_origin("20260102-030405")
    assert session_origin("bench") is None and session_origin(None) is None
    assert session_origin("20261399-000000") is None


def test_viewer_env_keeps_the_hosts_warnings_out_of_the_view_and_keeps_a_users_choice():
    env = viewer_env({"LANG": "C"})
    assert "re_viewer::native=error" in env["RUST_LOG"] and env["LC_ALL"] == "C.UTF-8" and env["XDG_RUNTIME_DIR"]
    assert viewer_env({"RUST_LOG": "debug", "LANG": "de_DE.UTF-8", "XDG_RUNTIME_DIR": "/run/u"}) == {
        "RUST_LOG": "debug", "LANG": "de_DE.UTF-8", "XDG_RUNTIME_DIR": "/run/u"}


def test_serve_needs_its_spec():
    with pytest.raises(ConfigError, match="mode 'serve' needs recording.rerun_serve"):
        RerunLogger("t", mode="serve")


def test_a_served_stream_listens_on_loopback_and_a_taken_port_is_an_oserror(tmp_path):
    port = free_tcp_port()
    spec = ServeSpec("127.0.0.1", port, 0, 8_000_000)
    with RerunLogger("t", "20260102-030405", "serve", tmp_path / "s.rrd", serve=spec) as rr:
        rr.log_scalars(0.0, T_in=1.0)
        rr.flush()
        with socket.create_connection(("127.0.0.1", port), timeout=2.0):
            pass
        assert rr.web_viewer is None and rr.mode == "serve"
        with pytest.raises(OSError, match=f"cannot serve on 127.0.0.1:{port}"):
            RerunLogger("t", "x", "serve", serve=spec)
    assert (tmp_path / "s.rrd").stat().st_size > 0              # served and saved


def test_teleop_view_web_prints_each_sides_page_opening_both_streams(tmp_path, capsys):
    cfg = tmp_path / "c.yaml"
    cfg.write_text("recording:\n  rerun_serve:\n    master_web_port: 0\n", encoding="utf-8")
    assert main(["view", "--config", str(cfg), "--web", "--slave", "10.0.0.2", "--master", "10.0.0.3"]) == 0
    (line,) = capsys.readouterr().out.splitlines()
    url = urlsplit(line.split(": ", 1)[1])
    assert (url.hostname, url.port) == ("10.0.0.2", 9097)
    assert parse_qs(url.query)["url"] == ["rerun+http://10.0.0.2:9877/proxy", "rerun+http://10.0.0.3:9878/proxy"]
