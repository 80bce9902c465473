"""The README's examples, run as written and in order (issue 33, item 2).

The README's fenced ``sh`` and ``python`` blocks are read from the file itself, so the test
cannot drift from it, and run in a folder laid out as a fresh clone (copies of ``config/``,
``data/`` and ``replays/``; ``tdmon`` on PATH is this tree's), against a real mosquitto and
real Zenoh sessions. What the test changes, it changes as a user could:

* ports: every loopback port of the commands and the daemon and broker files is moved to a
  free one (in the commands and in the copied files alike), and the broker's store lives in a
  folder of its own;
* the long ones are shortened through documented flags: ``tdmon publish`` of a CSV log at
  ``--speed 600 --limit 2700`` instead of 60 x for 5 min (the first 300 rows), of a WITS0
  session ``--limit 100`` frames. A shortened command must say in its comment how long it
  takes as written (the README says it for every command over a minute).

Conventions the README keeps (and this test checks): a command that runs ``until Ctrl-C``
(a daemon, the broker, the fleet's centre) says so in its comment and stands alone in its
block; it is started in the background, waited for (``tdmon run``: its "tdmon daemon
running" line; anything else: a port it names accepting connections) and stopped with SIGINT
(the user's Ctrl-C) at the next heading, after the blocks that use it. Other blocks run as
one shell script each, from the folder's root, and must exit 0. The set-up blocks (``bash
scripts/demo.sh``, ``bash scripts/test.sh``) are not run here: the second is CI itself, and
CI's wheel check runs the quick start again from an installed wheel (docs/ci.md).
"""

from __future__ import annotations

import os
import pwd
import re
import shutil
import signal
import socket
import subprocess
import sys
import tempfile
import time
from collections.abc import Iterator
from dataclasses import dataclass, field
from pathlib import Path

import pytest

pytestmark = pytest.mark.readme

REPO = Path(__file__).resolve().parents[2]
README = REPO / "README.md"
SETUP_SECTION = "Set-up on a fresh machine"
SETUP_COMMANDS = ["bash scripts/demo.sh", "bash scripts/test.sh"]
UNTIL_CTRL_C = re.compile(r"#\s*until Ctrl-C")
LOOPBACK_PORT = re.compile(r"(127\.0\.0\.1:)(\d+)")
#: ``tdmon publish`` of a CSV at 60 x: 10 x faster and its first 300 rows (9 channels each)
CSV_SHORTER = ("--speed 60", "--speed 600 --limit 2700")
#: ``tdmon publish --wits0``: the first 100 frames
WITS0_SHORTER = "--limit 100"
STOPPED = re.compile(r"tdmon: stopped: (\d+) samples, (\d+) rejected")


@dataclass(frozen=True)
class Block:
    section: str  # the heading above it
    language: str  # "sh" or "python"
    text: str
    line: int  # of the opening fence

    def commands(self) -> list[str]:
        """Logical lines: continuations joined, blank lines dropped."""
        joined = re.sub(r"\\\n\s*", " ", self.text)
        return [line.strip() for line in joined.splitlines() if line.strip()]


def readme_blocks(text: str) -> list[Block]:
    """The fenced ``sh`` and ``python`` blocks in order, each with its heading."""
    blocks: list[Block] = []
    section = ""
    fence: tuple[str, int, list[str]] | None = None
    for number, line in enumerate(text.splitlines(), start=1):
        if fence is None:
            if line.startswith("#"):
                section = line.lstrip("#").strip()
            elif line.startswith("```") and line[3:].strip() in ("sh", "python"):
                fence = (line[3:].strip(), number, [])
        elif line.startswith("```"):
            language, start, lines = fence
            blocks.append(Block(section, language, "\n".join(lines) + "\n", start))
            fence = None
        else:
            fence[2].append(line)
    return blocks


def without_comment(command: str) -> str:
    return re.sub(r"\s+#\s.*$", "", command)


def shortened(command: str) -> str:
    """The command with its documented flags for a shorter run, as the module docstring
    says; others unchanged."""
    if not command.startswith("tdmon publish"):
        return command
    bare = without_comment(command)
    if "--wits0" in bare:
        return f"{bare} {WITS0_SHORTER}"
    assert CSV_SHORTER[0] in bare, f"a publish the test cannot shorten: {command}"
    return bare.replace(*CSV_SHORTER)


def _free_port() -> int:
    with socket.socket(socket.AF_INET, socket.SOCK_STREAM) as sock:
        sock.bind(("127.0.0.1", 0))
        return int(sock.getsockname()[1])


def _accepts(port: int) -> bool:
    with socket.socket(socket.AF_INET, socket.SOCK_STREAM) as sock:
        sock.settimeout(0.5)
        return sock.connect_ex(("127.0.0.1", port)) == 0


def _for_mosquitto(path: Path) -> Path:
    """``path`` owned by user mosquitto when we are root (the broker drops to it)."""
    if os.geteuid() == 0:
        with_user = pwd.getpwnam("mosquitto")
        os.chown(path, with_user.pw_uid, with_user.pw_gid)
    return path


@dataclass
class Background:
    command: str
    process: subprocess.Popen[bytes]
    stderr: Path
    stdout: Path
    code: int | None = None


@dataclass
class Run:
    """What running the README left: per command its output and exit code."""

    folder: Path
    ports: dict[int, int]
    outputs: dict[str, tuple[int, str, str]] = field(default_factory=dict)
    stopped: list[Background] = field(default_factory=list)
    seconds: dict[str, float] = field(default_factory=dict)

    def output_of(self, prefix: str) -> tuple[int, str, str]:
        (found,) = [v for k, v in self.outputs.items() if k.startswith(prefix)]
        return found


class Workspace:
    """A fresh clone's layout with moved ports, and the processes started in it."""

    def __init__(self, folder: Path, broker_store: Path) -> None:
        self.folder = folder
        for name in ("config", "data", "replays"):
            shutil.copytree(REPO / name, folder / name)
        shutil.copy(README, folder / "README.md")
        blocks = readme_blocks(README.read_text())
        files = [*(folder / "config" / "daemon").glob("*.toml"),
                 folder / "config" / "mosquitto" / "tdmon.conf"]
        found = {int(m.group(2)) for b in blocks for m in LOOPBACK_PORT.finditer(b.text)}
        for path in files:
            text = path.read_text()
            found |= {int(m.group(2)) for m in LOOPBACK_PORT.finditer(text)}
            found |= {int(p) for p in re.findall(r"(?m)^(?:port =|listener) (\d+)", text)}
        self.ports = {port: _free_port() for port in sorted(found)}
        for path in files:
            text = self.moved(path.read_text())
            text = re.sub(r"(?m)^(port = |listener )(\d+)",
                          lambda m: f"{m.group(1)}{self.ports[int(m.group(2))]}", text)
            if path.suffix == ".conf":
                text = re.sub(r"(?m)^persistence_location .*$",
                              f"persistence_location {broker_store}/", text)
            path.write_text(text)
        bin_dir = folder / "bin"
        bin_dir.mkdir()
        shim = bin_dir / "tdmon"
        shim.write_text(f'#!/bin/sh\nexec "{sys.executable}" -m tdmon "$@"\n')
        shim.chmod(0o755)
        self.env = {**os.environ, "PYTHONPATH": str(REPO), "MPLBACKEND": "Agg",
                    "PATH": f"{bin_dir}:/usr/sbin:/sbin:{os.environ.get('PATH', '')}"}
        self.env.pop("TDMON_UNITS", None)
        self.background: list[Background] = []
        self.logs = folder / "logs"
        self.logs.mkdir()

    def moved(self, text: str) -> str:
        return LOOPBACK_PORT.sub(lambda m: f"{m.group(1)}{self.ports[int(m.group(2))]}", text)

    def start(self, command: str) -> Background:
        number = len(self.background) + len(list(self.logs.iterdir()))
        stdout, stderr = self.logs / f"{number}.out", self.logs / f"{number}.err"
        with stdout.open("wb") as out, stderr.open("wb") as err:
            process = subprocess.Popen(["bash", "-c", f"exec {command}"], cwd=self.folder,
                                       env=self.env, stdout=out, stderr=err,
                                       stdin=subprocess.DEVNULL, start_new_session=True)
        job = Background(command, process, stderr, stdout)
        self.background.append(job)
        self._wait_ready(job)
        return job

    def _wait_ready(self, job: Background) -> None:
        ports = [int(m.group(2)) for m in LOOPBACK_PORT.finditer(job.command)]
        config = re.search(r"mosquitto -c (\S+)", job.command)
        if config is not None:
            ports += [int(p) for p in re.findall(r"(?m)^listener (\d+)",
                                                 (self.folder / config.group(1)).read_text())]
        daemon = job.command.startswith("tdmon run")
        assert daemon or ports, f"no way to tell when it is ready: {job.command}"
        deadline = time.monotonic() + 180
        while time.monotonic() < deadline:
            if job.process.poll() is not None:
                raise AssertionError(f"{job.command} exited with {job.process.returncode}: "
                                     f"{job.stderr.read_text()[-2000:]}")
            if daemon and "tdmon daemon running" in job.stderr.read_text():
                return
            if not daemon and any(_accepts(port) for port in ports):
                return
            time.sleep(0.2)
        raise AssertionError(f"not ready after 180 s: {job.command}")

    def stop_all(self) -> list[Background]:
        """Ctrl-C to each background command, newest first (the rig before its broker)."""
        stopped = []
        for job in reversed(self.background):
            if job.process.poll() is None:
                os.killpg(job.process.pid, signal.SIGINT)
            try:
                job.code = job.process.wait(timeout=120)
            except subprocess.TimeoutExpired:
                os.killpg(job.process.pid, signal.SIGKILL)
                job.code = job.process.wait()
            stopped.append(job)
        self.background = []
        return stopped

    def run_block(self, block: Block) -> tuple[int, str, str]:
        if block.language == "python":
            argv = [sys.executable, "-c", block.text]
        else:
            script = "\n".join(self.moved(shortened(c)) for c in block.commands())
            argv = ["bash", "-c", f"set -euo pipefail\n{script}"]
        done = subprocess.run(argv, cwd=self.folder, env=self.env, capture_output=True,
                              text=True, timeout=900, stdin=subprocess.DEVNULL)
        return done.returncode, done.stdout, done.stderr


@pytest.fixture(scope="module")
def ran(tmp_path_factory: pytest.TempPathFactory) -> Iterator[Run]:
    store = _for_mosquitto(Path(tempfile.mkdtemp(prefix="tdmon-readme-broker-")))
    workspace = Workspace(tmp_path_factory.mktemp("readme"), store)
    run = Run(workspace.folder, workspace.ports)
    section = None
    try:
        for block in readme_blocks(README.read_text()):
            if block.section != section:
                run.stopped += workspace.stop_all()
                section = block.section
            if block.section.startswith(SETUP_SECTION):
                continue
            commands = block.commands()
            start = time.monotonic()
            if any(UNTIL_CTRL_C.search(c) for c in commands):
                assert len(commands) == 1, f"README line {block.line}: a command that runs " \
                                           "until Ctrl-C stands alone in its block"
                workspace.start(workspace.moved(commands[0]))
            else:
                code, out, err = workspace.run_block(block)
                assert code == 0, (f"README line {block.line} ({block.section}) exited "
                                   f"{code}:\n{block.text}\n{out[-3000:]}\n{err[-3000:]}")
                run.outputs[block.text] = (code, out, err)
            run.seconds[f"line {block.line}: {commands[0][:60]}"] = time.monotonic() - start
        run.stopped += workspace.stop_all()
        yield run
    finally:
        workspace.stop_all()
        shutil.rmtree(store, ignore_errors=True)
        for name, seconds in run.seconds.items():
            print(f"{seconds:6.1f} s  {name}")


def _stopped(run: Run, config: str) -> Background:
    (job,) = [j for j in run.stopped if j.command.startswith("tdmon run") and config in j.command]
    return job


def test_the_setup_blocks_are_the_two_commands_and_nothing_else_is_skipped() -> None:
    blocks = readme_blocks(README.read_text())
    setup = [c for b in blocks if b.section.startswith(SETUP_SECTION) for c in b.commands()]
    assert setup == SETUP_COMMANDS
    assert len(blocks) >= 15


def test_shortened_commands_say_how_long_they_take_as_written() -> None:
    for block in readme_blocks(README.read_text()):
        for command in block.commands():
            if shortened(command) != command:
                assert re.search(r"\d+ (min|s)\b", command), \
                    f"README line {block.line}: {command}"


def test_every_example_ran(ran: Run) -> None:
    run_blocks = [b for b in readme_blocks(README.read_text())
                  if not b.section.startswith(SETUP_SECTION)]
    background = [b for b in run_blocks if any(UNTIL_CTRL_C.search(c) for c in b.commands())]
    assert len(ran.outputs) == len({b.text for b in run_blocks}) - len(background)
    # every daemon, broker and centre stopped on Ctrl-C with exit code 0
    assert len(ran.stopped) == len(background) >= 6
    for job in ran.stopped:
        assert job.code == 0, f"{job.command}: {job.code}\n{job.stderr.read_text()[-2000:]}"


@pytest.mark.parametrize("config", ["zenoh-local.toml", "mqtt-local.toml", "fleet-zenoh.toml"])
def test_each_live_daemon_took_every_sample_of_the_rig(ran: Run, config: str) -> None:
    # issue 33: a session of another well was "beyond the well"; a daemon that heard nothing
    # showed "0 rigs"
    job = _stopped(ran, config)
    found = STOPPED.search(job.stderr.read_text())
    assert found is not None, job.stderr.read_text()[-2000:]
    samples, rejected = int(found.group(1)), int(found.group(2))
    assert samples >= 2000 and rejected == 0


def test_the_live_daemons_wrote_their_recordings_and_views(ran: Run) -> None:
    out = ran.folder / "out"
    for name in ("zenoh-local", "mqtt-local"):
        assert (out / f"{name}.rrd").stat().st_size > 10_000
    assert len(list((out / "recordings").glob("*.mcap"))) >= 2


def test_the_fleet_table_shows_the_rig(ran: Run) -> None:
    _, out, _ = ran.output_of("tdmon publish data/volve-f4/trip-in-2016-10-05.csv --prefix")
    table = out.strip().splitlines()
    assert table[0].startswith("tdmon fleet ") and table[0].endswith(" 1 rig")
    assert any(line.startswith("rig/F4 ") for line in table)


def test_the_python_example_printed_its_recording(ran: Run) -> None:
    (_, out, _), = [v for k, v in ran.outputs.items() if k.startswith("import tdmon")]
    assert out.startswith("Recording('out/trip-in-api.mcap', messages: /tdmon/alarm ")
    assert "pick_up" in out and "hookload_N" in out
