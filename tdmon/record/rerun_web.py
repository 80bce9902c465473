"""Rerun's web viewer for a browser, served on loopback beside a live Rerun view.

``tdmon run --web`` and ``tdmon fleet --web`` start it: the daemon (or the fleet) serves its
Rerun recording over gRPC on ``127.0.0.1:<rerun port>`` (:class:`~tdmon.record.rerun_views.
RerunViews`), and this serves the viewer's page and WebAssembly on ``127.0.0.1:<web port>``;
the page, opened at :attr:`WebViewer.url`, connects to the gRPC stream itself and lays it out
with the recording's blueprint.

The viewer is the ``rerun`` executable of the rerun-sdk package in a child process, because
it can bind 127.0.0.1 (``--bind``): the SDK's ``serve_web_viewer`` listens on every interface,
and a rig network is not a place for an open port.
"""

from __future__ import annotations

import importlib.util
import socket
import subprocess
import sys
import tempfile
import time
from pathlib import Path
from typing import Final
from urllib.parse import quote

from tdmon.errors import RecordError

__all__ = ["DEFAULT_WEB_PORT", "WebViewer"]

#: The web viewer's default port (Rerun's own default).
DEFAULT_WEB_PORT: Final = 9090
#: How long the viewer's server may take to listen [s] (a loaded machine: several seconds).
START_TIMEOUT_S: Final = 60.0


def rerun_binary() -> Path:
    """The ``rerun`` executable rerun-sdk installs (in its ``rerun_cli`` package). Run
    directly: ``python -m rerun`` wraps it in a Python process that would not pass a
    terminate on."""
    spec = importlib.util.find_spec("rerun_cli")
    if spec is None or spec.origin is None:
        raise RecordError("Rerun's web viewer needs the rerun-sdk package (its rerun_cli)")
    binary = Path(spec.origin).parent / ("rerun.exe" if sys.platform.startswith("win")
                                         else "rerun")
    if not binary.exists():
        raise RecordError(f"Rerun's web viewer: no rerun executable at {binary}")
    return binary


class WebViewer:
    """The web viewer of the gRPC stream ``grpc_uri``, served on ``127.0.0.1:port`` until
    :meth:`close` (a context manager)."""

    def __init__(self, grpc_uri: str, port: int = DEFAULT_WEB_PORT,
                 start_timeout_s: float = START_TIMEOUT_S) -> None:
        self.grpc_uri = grpc_uri
        self.port = port
        self.url = f"http://127.0.0.1:{port}/?url={quote(grpc_uri, safe=':/')}"
        # its messages to a file, not a pipe nobody reads while it runs (a full pipe blocks it)
        self._log = tempfile.TemporaryFile()  # noqa: SIM115  (closed by close())
        try:
            self._process = subprocess.Popen(
                [str(rerun_binary()), "--serve-web", "--bind", "127.0.0.1",
                 "--web-viewer-port", str(port), grpc_uri],
                stdin=subprocess.DEVNULL, stdout=self._log, stderr=subprocess.STDOUT)
        except OSError as exc:
            self._log.close()
            raise RecordError(f"cannot start Rerun's web viewer: {exc.strerror or exc}") from exc
        try:
            self._wait_listening(start_timeout_s)
        except RecordError:
            self.close()
            raise

    def _wait_listening(self, timeout_s: float) -> None:
        deadline = time.monotonic() + timeout_s
        while True:
            if self._process.poll() is not None:
                self._log.seek(0)
                error = self._log.read().decode(errors="replace")
                last = error.strip().splitlines()[-1] if error.strip() else ""
                raise RecordError(f"Rerun's web viewer stopped on start "
                                  f"({self._process.returncode}){': ' + last if last else ''}")
            try:
                with socket.create_connection(("127.0.0.1", self.port), timeout=0.5):
                    return
            except OSError:
                pass
            if time.monotonic() > deadline:
                raise RecordError(f"Rerun's web viewer did not listen on 127.0.0.1:{self.port} "
                                  f"within {timeout_s:g} s")
            time.sleep(0.1)

    def close(self) -> None:
        """Stop the viewer's server; safe to call twice."""
        if self._process.poll() is None:
            self._process.terminate()
            try:
                self._process.wait(timeout=5.0)
            except subprocess.TimeoutExpired:
                self._process.kill()
                self._process.wait()
        self._log.close()

    def __enter__(self) -> WebViewer:
        return self

    def __exit__(self, *exc_info: object) -> None:
        self.close()
