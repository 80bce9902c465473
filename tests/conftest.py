"""Shared fixtures: a real mosquitto broker on a free loopback port, and free ports for Zenoh.

Broker fixtures are synchronous (a subprocess), so they work with any event loop scope.
"""

from __future__ import annotations

import os
import pwd
import shutil
import signal
import socket
import subprocess
import tempfile
import time
from collections.abc import Callable, Iterator
from pathlib import Path

import pytest

from tdmon.blas import limit_blas_threads

# the tests' small matrices, like the command line's, on one BLAS thread (tdmon/blas.py)
limit_blas_threads()

MOSQUITTO = shutil.which("mosquitto") or "/usr/sbin/mosquitto"
#: The broker configuration tdmon ships (docs/daemon.md, "The broker").
SHIPPED_CONF = Path(__file__).resolve().parents[1] / "config" / "mosquitto" / "tdmon.conf"
#: Lines of the shipped file a test broker replaces: its port, store and log are its own.
_REPLACED = ("listener", "persistence_location", "log_dest", "allow_anonymous")


def free_port() -> int:
    """A TCP port on 127.0.0.1 that nothing listens on right now."""
    with socket.socket(socket.AF_INET, socket.SOCK_STREAM) as sock:
        sock.bind(("127.0.0.1", 0))
        return int(sock.getsockname()[1])


def _chown_to_mosquitto(path: Path) -> None:
    # mosquitto started as root drops to user "mosquitto" before reading its files
    if os.geteuid() != 0:
        return
    try:
        entry = pwd.getpwnam("mosquitto")
    except KeyError:
        return
    os.chown(path, entry.pw_uid, entry.pw_gid)


class Mosquitto:
    """A mosquitto process on 127.0.0.1:``port`` with its config in ``workdir``."""

    def __init__(self, workdir: Path, port: int | None = None, extra: str = "",
                 persistence: bool = False, listener_extra: str = "",
                 allow_anonymous: bool = True, shipped: bool = False,
                 overrides: dict[str, str] | None = None) -> None:
        """``shipped``: start from config/mosquitto/tdmon.conf (persistence on) with this
        broker's port, store and log; ``overrides`` replace its settings by key."""
        self.workdir = workdir
        self.port = port or free_port()
        self.process: subprocess.Popen[bytes] | None = None
        workdir.mkdir(parents=True, exist_ok=True)
        _chown_to_mosquitto(workdir)
        if shipped:
            self._write_config(self._shipped_lines(overrides or {}))
            return
        lines = [
            "per_listener_settings true",
            f"listener {self.port} 127.0.0.1",
            f"allow_anonymous {'true' if allow_anonymous else 'false'}",
            listener_extra,
            "max_queued_messages 1000000",
            "max_inflight_messages 100",
            "set_tcp_nodelay true",
            f"log_dest file {workdir / 'mosquitto.log'}",
            "log_type error",
            "log_type warning",
            "log_type notice",
        ]
        if persistence:
            store = workdir / "store"
            store.mkdir(exist_ok=True)
            _chown_to_mosquitto(store)
            lines += ["persistence true", f"persistence_location {store}/",
                      "autosave_interval 1"]
        lines.append(extra)
        self._write_config(lines)

    def _shipped_lines(self, overrides: dict[str, str]) -> list[str]:
        store = self.workdir / "store"
        store.mkdir(exist_ok=True)
        _chown_to_mosquitto(store)
        lines = [f"listener {self.port} 127.0.0.1", "allow_anonymous true",
                 f"persistence_location {store}/",
                 f"log_dest file {self.workdir / 'mosquitto.log'}"]
        for line in SHIPPED_CONF.read_text().splitlines():
            setting = line.split("#", 1)[0].split()
            key = setting[0] if setting else ""
            if not key or key in _REPLACED:
                continue
            lines.append(f"{key} {overrides.pop(key)}" if key in overrides else line)
        lines += [f"{key} {value}" for key, value in overrides.items()]
        return lines

    def _write_config(self, lines: list[str]) -> None:
        self.config = self.workdir / "mosquitto.conf"
        self.config.write_text("\n".join(line for line in lines if line) + "\n")
        (self.workdir / "mosquitto.log").touch()
        _chown_to_mosquitto(self.workdir / "mosquitto.log")

    def start(self) -> None:
        self.process = subprocess.Popen([MOSQUITTO, "-c", str(self.config)],
                                        stdout=subprocess.DEVNULL, stderr=subprocess.PIPE)
        deadline = time.monotonic() + 10
        while time.monotonic() < deadline:
            if self.process.poll() is not None:
                err = self.process.stderr.read().decode() if self.process.stderr else ""
                log = (self.workdir / "mosquitto.log").read_text()
                raise RuntimeError(f"mosquitto exited: {err} {log}")
            try:
                with socket.create_connection(("127.0.0.1", self.port), timeout=0.2):
                    return
            except OSError:
                time.sleep(0.05)
        raise RuntimeError(f"mosquitto did not listen on {self.port}")

    def stop(self) -> None:
        if self.process is None:
            return
        # SIGTERM lets mosquitto write its persistence database before exiting
        self.process.send_signal(signal.SIGTERM)
        try:
            self.process.wait(10)
        except subprocess.TimeoutExpired:
            self.process.kill()
            self.process.wait()
        if self.process.stderr:
            self.process.stderr.close()
        self.process = None

    def restart(self) -> None:
        self.stop()
        self.start()

    @property
    def log(self) -> str:
        return (self.workdir / "mosquitto.log").read_text()


@pytest.fixture(scope="session")
def free_tcp_port() -> Callable[[], int]:
    """``free_tcp_port()`` gives a loopback port nothing listens on (tests import no helpers
    from this file: several conftest modules share the name once the whole suite runs)."""
    return free_port


@pytest.fixture
def broker_dir() -> Iterator[Path]:
    """A folder mosquitto can use after dropping to its own user.

    pytest's tmp_path sits under root-only folders that user "mosquitto" cannot enter, so
    the broker's files (log, persistence store, certificates) live in their own folder.
    """
    folder = Path(tempfile.mkdtemp(prefix="tdmon-mosquitto-"))
    folder.chmod(0o755)
    _chown_to_mosquitto(folder)
    try:
        yield folder
    finally:
        shutil.rmtree(folder, ignore_errors=True)


@pytest.fixture
def mosquitto(broker_dir: Path) -> Iterator[Mosquitto]:
    """An anonymous broker with persistence, started and stopped around the test."""
    broker = Mosquitto(broker_dir / "broker", persistence=True)
    broker.start()
    try:
        yield broker
    finally:
        broker.stop()


@pytest.fixture
def shipped_mosquitto(broker_dir: Path) -> Iterator[Callable[..., Mosquitto]]:
    """``shipped_mosquitto(**overrides)``: a started broker with the shipped configuration
    (config/mosquitto/tdmon.conf) on a free port, its store in a temporary folder; keyword
    arguments replace settings (``max_queued_messages="50"``). Stopped after the test."""
    started: list[Mosquitto] = []

    def make(**overrides: str) -> Mosquitto:
        broker = Mosquitto(broker_dir / f"shipped{len(started)}", shipped=True,
                           overrides=overrides)
        broker.start()
        started.append(broker)
        return broker

    try:
        yield make
    finally:
        for broker in started:
            broker.stop()


@pytest.fixture
def tls_mosquitto(broker_dir: Path) -> Iterator[tuple[Mosquitto, Path, str, str]]:
    """A TLS broker with a password file: (broker, CA file, username, password)."""
    certs = broker_dir / "certs"
    certs.mkdir()
    _make_certs(certs)
    passwords = certs / "passwd"
    passwords.touch()
    subprocess.run(["mosquitto_passwd", "-b", str(passwords), "rig", "s3cret"], check=True,
                   capture_output=True)
    for path in (certs, *certs.iterdir()):
        _chown_to_mosquitto(path)
    os.chmod(passwords, 0o600)
    listener_extra = "\n".join([
        f"cafile {certs / 'ca.crt'}",
        f"certfile {certs / 'server.crt'}",
        f"keyfile {certs / 'server.key'}",
        f"password_file {passwords}",
    ])
    broker = Mosquitto(broker_dir / "broker", listener_extra=listener_extra, allow_anonymous=False)
    broker.start()
    try:
        yield broker, certs / "ca.crt", "rig", "s3cret"
    finally:
        broker.stop()


def _make_certs(folder: Path) -> None:
    """A throw-away CA and a server certificate for 127.0.0.1/localhost (openssl)."""
    def run(*args: str) -> None:
        subprocess.run(["openssl", *args], check=True, capture_output=True, cwd=folder)

    run("req", "-x509", "-newkey", "rsa:2048", "-nodes", "-days", "2", "-subj", "/CN=tdmon test CA",
        "-keyout", "ca.key", "-out", "ca.crt")
    run("req", "-newkey", "rsa:2048", "-nodes", "-subj", "/CN=localhost",
        "-keyout", "server.key", "-out", "server.csr")
    (folder / "san.ext").write_text("subjectAltName=IP:127.0.0.1,DNS:localhost\n")
    run("x509", "-req", "-in", "server.csr", "-CA", "ca.crt", "-CAkey", "ca.key",
        "-CAcreateserial", "-days", "2", "-out", "server.crt", "-extfile", "san.ext")


#: The fault-injection tests of docs/reliability.md, one command: ``pytest -m faults``.
FAULT_TEST_FILES = frozenset({
    "test_clock_faults.py", "test_delivery_sigkill.py", "test_seq_outage.py",
    "test_mqtt_delivery.py", "test_publish_reconnect.py", "test_oversize_payloads.py",
    "test_recovery_alarm.py", "test_recovery_and_retries.py", "test_nonmcap.py",
    "test_startup_errors.py", "test_misleading_inputs.py", "test_password_file.py",
    "test_broker_restart.py", "test_crash_recovery.py", "test_recorder_failure.py",
    "test_crash_and_failure.py", "test_tls.py", "test_fuzz_daemon.py",
})


def pytest_collection_modifyitems(config: pytest.Config, items: list[pytest.Item]) -> None:
    """Mark the fault-injection tests (``-m faults``) by their file."""
    for item in items:
        if item.path.name in FAULT_TEST_FILES:
            item.add_marker(pytest.mark.faults)


@pytest.fixture(scope="session")
def chromium() -> str:
    """The headless Chromium the browser tests drive (``TDMON_CHROMIUM`` names another): the
    test fails without it, as scripts/test.sh installs it."""
    for name in (os.environ.get("TDMON_CHROMIUM"), "chromium", "chromium-browser",
                 "google-chrome"):
        found = shutil.which(name) if name else None
        if found:
            return found
    pytest.fail("headless Chromium not found: scripts/test.sh installs it "
                "(apt-get install chromium), or set TDMON_CHROMIUM")
