"""``--web``: Rerun's web viewer served on loopback beside the live Rerun view, loaded in
headless Chromium (installed by ``scripts/test.sh``; the test fails without it)."""

from __future__ import annotations

import json
import os
import signal
import subprocess
import sys
import threading
import time
import urllib.request
from collections.abc import Callable
from pathlib import Path

import psutil
import pytest
import zenoh

from tdmon.cli import main
from tdmon.cli.run import served_live
from tdmon.config.daemon import load_daemon_config
from tdmon.errors import ConfigError
from tdmon.record.rerun_web import WebViewer

ROOT = Path(__file__).resolve().parents[2]


def _listening(port: int) -> list[str]:
    return [c.laddr.ip for c in psutil.net_connections("tcp")
            if c.status == psutil.CONN_LISTEN and c.laddr.port == port]


def test_the_web_viewer_listens_on_loopback_only(free_tcp_port: Callable[[], int]) -> None:
    port = free_tcp_port()
    with WebViewer("rerun+http://127.0.0.1:9876/proxy", port) as viewer:
        assert _listening(port) and set(_listening(port)) == {"127.0.0.1"}
        with urllib.request.urlopen(f"http://127.0.0.1:{port}/", timeout=30) as page:
            assert b"web viewer" in page.read().lower()
        assert viewer.url == (f"http://127.0.0.1:{port}/?url="
                              "rerun%2Bhttp://127.0.0.1:9876/proxy")
    assert _listening(port) == []  # stopped with the viewer


def test_run_web_serves_the_views_live(capsys: pytest.CaptureFixture[str],
                                       free_tcp_port: Callable[[], int]) -> None:
    config = load_daemon_config(ROOT / "config" / "daemon" / "zenoh-local.toml")
    live = served_live(config, Path("zenoh-local.toml"))
    assert (live.rerun.mode, live.rerun.path) == ("live", config.rerun.path)
    fleet = load_daemon_config(ROOT / "config" / "daemon" / "fleet-zenoh.toml")
    with pytest.raises(ConfigError, match="tdmon fleet --web"):
        served_live(fleet, Path("fleet-zenoh.toml"))
    # a web port in use stops the start with one line
    with __import__("socket").socket() as holder:
        holder.bind(("127.0.0.1", 0))
        holder.listen()
        taken = holder.getsockname()[1]
        assert main(["run", "--config", str(ROOT / "config" / "daemon" / "zenoh-local.toml"),
                     "--web", "--web-port", str(taken)]) == 2
    assert f"--web-port {taken}: cannot serve the web viewer" in capsys.readouterr().err


def _browser_connections(browser: psutil.Process, port: int) -> int:
    """Connections of the browser's processes to the Rerun stream's port."""
    processes = [browser, *browser.children(recursive=True)]
    pids = {p.pid for p in processes}
    return sum(1 for c in psutil.net_connections("tcp")
               if c.pid in pids and c.raddr and c.raddr.port == port
               and c.status == psutil.CONN_ESTABLISHED)


def test_fleet_web_view_loads_in_a_browser(tmp_path: Path, free_tcp_port: Callable[[], int],
                                           chromium: str) -> None:
    router, rerun_port, web_port = free_tcp_port(), free_tcp_port(), free_tcp_port()
    env = {**os.environ, "PYTHONPATH": str(ROOT)}
    fleet = subprocess.Popen(
        [sys.executable, "-m", "tdmon", "fleet", "--listen", f"tcp/127.0.0.1:{router}",
         "--web", "--rerun-port", str(rerun_port), "--web-port", str(web_port),
         "--duration", "120 s", "--interval", "30 s"],
        stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True, env=env, cwd=tmp_path)
    lines: list[str] = []
    reader = threading.Thread(target=lambda: lines.extend(fleet.stderr or []), daemon=True)
    reader.start()
    browser = None
    try:
        deadline = time.monotonic() + 90
        while not any("web view: " in line for line in lines):
            assert fleet.poll() is None, "".join(lines)
            assert time.monotonic() < deadline, "no web view announced: " + "".join(lines)
            time.sleep(0.05)
        url = next(line for line in lines if "web view: " in line).split("web view: ")[1]
        assert url.strip() == (f"http://127.0.0.1:{web_port}/?url=rerun%2Bhttp://127.0.0.1:"
                               f"{rerun_port}/proxy")
        assert set(_listening(web_port)) == {"127.0.0.1"}
        # a rig's result, so that the stream has a friction to show
        session = zenoh.open(zenoh.Config.from_json5(json.dumps({
            "mode": "peer", "connect": {"endpoints": [f"tcp/127.0.0.1:{router}"]},
            "scouting": {"multicast": {"enabled": False}, "gossip": {"enabled": False}}})))
        try:
            session.put("rig/A/tdmon/estimate", json.dumps(
                {"t": 1.0, "kind": "window", "operation": "pick_up", "mu": 0.25,
                 "mu_std": 0.01}))
            # one browser start: the page loads the viewer, which connects to the stream
            browser = psutil.Process(subprocess.Popen(
                [chromium, "--headless", "--no-sandbox", "--use-angle=swiftshader",
                 "--enable-unsafe-swiftshader", "--no-first-run", "--remote-debugging-port=0",
                 f"--user-data-dir={tmp_path / 'chromium-profile'}", "--window-size=1200,800",
                 url.strip()], stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL).pid)
            deadline = time.monotonic() + 90
            while _browser_connections(browser, rerun_port) == 0:
                assert browser.is_running(), "Chromium ended"
                assert time.monotonic() < deadline, "the viewer never connected to the stream"
                time.sleep(0.2)
        finally:
            session.close()
    finally:
        if browser is not None:
            for process in [*browser.children(recursive=True), browser]:
                process.kill()
            psutil.wait_procs([browser], timeout=10)
        fleet.send_signal(signal.SIGTERM)
        code = fleet.wait(timeout=60)
    assert code == 0, "".join(lines)
    assert _listening(web_port) == []  # the web viewer stopped with the fleet
