"""``tdmon run --config ...`` stops at start with one line and exit code 2 on the mistakes that
used to surface only later (issue 13, item 5): a missing or unusable TLS file (retried for
ever), a Rerun live port in use (no viewer, a traceback at shutdown), an unset password
variable. A real mosquitto listens where the files point."""

from __future__ import annotations

import os
import socket
import subprocess
import sys
from pathlib import Path
from typing import Any

import pytest

ROOT = Path(__file__).resolve().parents[2]
REPLAY = ROOT / "replays" / "faults-limits.mcap"


def run_tdmon(config: Path, env: dict[str, str] | None = None) -> subprocess.CompletedProcess[str]:
    """``tdmon run --config`` as a user runs it; it must end by itself (generous timeout)."""
    return subprocess.run(
        [sys.executable, "-m", "tdmon", "run", "--config", str(config)],
        capture_output=True, text=True, timeout=120, cwd=ROOT,
        env={**os.environ, "PYTHONPATH": str(ROOT), **(env or {})})


def one_error_line(result: subprocess.CompletedProcess[str]) -> str:
    assert result.returncode == 2, result.stderr
    errors = [line for line in result.stderr.splitlines() if "error" in line.lower()]
    assert len(errors) == 1, result.stderr
    assert "Traceback" not in result.stderr
    assert errors[0].startswith("tdmon: error: ")
    return errors[0]


def write(path: Path, text: str) -> Path:
    path.write_text(text)
    return path


def test_missing_ca_file_names_key_and_resolved_path(mosquitto: Any, tmp_path: Path) -> None:
    config = write(tmp_path / "daemon.toml", f'''prefix = "rig/T1"
[sources.mqtt]
port = {mosquitto.port}
[sources.mqtt.tls]
ca_file = "certs/ca.crt"
''')
    line = one_error_line(run_tdmon(config))
    assert line == (f"tdmon: error: {config}: sources.mqtt.tls.ca_file: no such file: "
                    f"{(tmp_path / 'certs' / 'ca.crt').resolve()}")


def test_unreadable_ca_file_is_refused_at_start(mosquitto: Any, tmp_path: Path) -> None:
    (tmp_path / "ca.crt").write_text("not a certificate\n")
    config = write(tmp_path / "daemon.toml", f'''prefix = "rig/T1"
[sources.mqtt]
port = {mosquitto.port}
[sources.mqtt.tls]
ca_file = "ca.crt"
''')
    line = one_error_line(run_tdmon(config))
    assert line.startswith(f"tdmon: error: {config}: sources.mqtt: TLS tls.ca_file "
                           f"{tmp_path / 'ca.crt'}: ")


def test_publisher_tls_key_file_missing(mosquitto: Any, tmp_path: Path) -> None:
    (tmp_path / "client.crt").write_text("x")
    config = write(tmp_path / "daemon.toml", f'''prefix = "rig/T1"
[sources.mcap]
path = "{REPLAY}"
[publish.mqtt]
port = {mosquitto.port}
[publish.mqtt.tls]
cert_file = "client.crt"
key_file = "client.key"
''')
    line = one_error_line(run_tdmon(config))
    assert line.endswith(f"publish.mqtt.tls.key_file: no such file: "
                         f"{(tmp_path / 'client.key').resolve()}")


def test_rerun_live_port_in_use(tmp_path: Path) -> None:
    with socket.socket(socket.AF_INET, socket.SOCK_STREAM) as holder:
        holder.bind(("127.0.0.1", 0))
        holder.listen(1)
        port = holder.getsockname()[1]
        config = write(tmp_path / "daemon.toml", f'''prefix = "sim/faults"
[sources.mcap]
path = "{REPLAY}"
[rerun]
mode = "live"
port = {port}
''')
        result = run_tdmon(config)
    line = one_error_line(result)
    assert line == (f"tdmon: error: {config}: rerun.port: cannot serve the live viewer on "
                    f"127.0.0.1:{port}: Address already in use; choose another port or stop "
                    "what holds it")


def test_port_check_sees_a_free_port(free_tcp_port: Any) -> None:
    from tdmon.cli.run import port_in_use

    port = free_tcp_port()
    assert port_in_use("127.0.0.1", port) is None
    with socket.socket(socket.AF_INET, socket.SOCK_STREAM) as holder:
        holder.bind(("127.0.0.1", port))
        holder.listen(1)
        assert port_in_use("127.0.0.1", port) == "Address already in use"


@pytest.mark.parametrize("section", ["sources.mqtt", "publish.mqtt"])
def test_unset_password_variable(mosquitto: Any, tmp_path: Path, section: str) -> None:
    source = "" if section == "sources.mqtt" else f'[sources.mcap]\npath = "{REPLAY}"\n'
    config = write(tmp_path / "daemon.toml", f'''prefix = "rig/T1"
{source}[{section}]
port = {mosquitto.port}
username = "rig"
password_env = "TDMON_TEST_NO_SUCH_PASSWORD"
''')
    env = {k: v for k, v in os.environ.items() if k != "TDMON_TEST_NO_SUCH_PASSWORD"}
    result = subprocess.run(
        [sys.executable, "-m", "tdmon", "run", "--config", str(config)],
        capture_output=True, text=True, timeout=120, cwd=ROOT,
        env={**env, "PYTHONPATH": str(ROOT)})
    assert one_error_line(result) == (
        f"tdmon: error: {config}: {section}.password_env: environment variable "
        "TDMON_TEST_NO_SUCH_PASSWORD is not set")


def test_clear_text_password_readable_by_others_warns_once(mosquitto: Any,
                                                           tmp_path: Path) -> None:
    """The warning comes at start, before anything else fails (here: the missing CA)."""
    secret = write(tmp_path / "mqtt.pw", "s3cret\n")
    secret.chmod(0o644)
    config = write(tmp_path / "daemon.toml", f'''prefix = "rig/T1"
[sources.mqtt]
port = {mosquitto.port}
username = "rig"
password_file = "mqtt.pw"
[sources.mqtt.tls]
ca_file = "absent.crt"
''')
    result = run_tdmon(config)
    one_error_line(result)
    warnings = [line for line in result.stderr.splitlines() if "WARNING" in line]
    assert len(warnings) == 1
    assert warnings[0].endswith(f"{secret} holds a clear-text password "
                                f"(sources.mqtt.password_file) and is readable by others "
                                f"(mode 644): chmod 600 {secret}")
