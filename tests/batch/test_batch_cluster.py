"""``tdmon batch`` on a real Dask cluster of worker processes on 127.0.0.1: replays finish
beside a broken and a missing file, the recordings and the summary match what the replays
recorded, BLAS is held to one thread inside the tasks.

The cluster's workers start with ``OPENBLAS_NUM_THREADS=2`` (Dask's nanny would set 1 by
itself), so the cap measured inside a task is the task's own doing.
"""

from __future__ import annotations

from collections.abc import Iterator
from pathlib import Path
from typing import Any

import pandas as pd
import pytest

from tdmon.cli import main
from tdmon.record.reader import read_messages, topic_counts
from tdmon.replay.batch import run_batch

REPO = Path(__file__).resolve().parents[2]
SHORT = REPO / "replays" / "trip-in-noisy.mcap"  # 965 input messages, about 1 s
CONFIG = REPO / "config" / "daemon" / "replay-sim-trip-in.toml"


@pytest.fixture(scope="module")
def cluster() -> Iterator[Any]:
    from distributed import LocalCluster

    with LocalCluster(n_workers=2, threads_per_worker=1, processes=True, host="127.0.0.1",
                      dashboard_address="127.0.0.1:0",
                      env={"OPENBLAS_NUM_THREADS": "2"}) as local:
        yield local


@pytest.fixture
def broken(tmp_path: Path) -> Path:
    path = tmp_path / "broken.mcap"
    path.write_text("time,hookload\n0,1\n")
    return path


def _blas_threads_outside_tasks() -> int:
    # numpy's and scipy's own OpenBLAS: a worker may load numpy's before its environment is
    # applied (1 thread), scipy's comes up at the workers' 2 threads
    import numpy  # noqa: F401
    import scipy.linalg  # noqa: F401
    from threadpoolctl import threadpool_info

    return max(pool["num_threads"] for pool in threadpool_info() if pool["user_api"] == "blas")


def test_batch_on_a_cluster_isolates_failures(cluster: Any, broken: Path,
                                              tmp_path: Path) -> None:
    from distributed import Client

    missing = tmp_path / "missing.mcap"
    with Client(cluster) as client:
        outside = client.run(_blas_threads_outside_tasks)
    assert set(outside.values()) == {2}, "the workers' BLAS must start above the cap"

    done: list[tuple[int, int]] = []
    result = run_batch([SHORT, broken, missing, SHORT], tmp_path / "out", config=CONFIG,
                       scheduler=cluster.scheduler_address,
                       progress=lambda outcome, n, total: done.append((n, total)))
    assert sorted(done) == [(1, 4), (2, 4), (3, 4), (4, 4)]
    ok, bad, gone, again = result.outcomes
    assert bad.error is not None and "not an MCAP file" in bad.error and "import csv" in bad.error
    assert gone.error is not None and "replay not found" in gone.error
    assert [o.ok for o in result.outcomes] == [True, False, False, True]
    assert ok.blas_threads == 1 and again.blas_threads == 1

    # the recordings are the daemon's flight recordings of the replays, one file each
    assert Path(ok.out or "").name == "trip-in-noisy.mcap"
    assert Path(again.out or "").name == "trip-in-noisy-2.mcap"
    counts = topic_counts(ok.out or "")
    assert counts["/tdmon/raw"] == ok.messages_in == topic_counts(SHORT)["/tdmon/raw"] == 965
    windows = [m.message for m in read_messages(ok.out or "", "/tdmon/estimate")
               if m.message["kind"] == "window"]
    assert len(ok.windows) == len(windows) > 5
    alarms = list(read_messages(ok.out or "", "/tdmon/alarm"))
    assert sum(ok.alarms.values()) == len(alarms)

    # the summary read back from its files
    summary = tmp_path / "out" / "summary"
    recordings = pd.read_parquet(summary / "recordings.parquet")
    assert recordings["status"].tolist() == ["ok", "failed", "failed", "ok"]
    friction = pd.read_parquet(summary / "friction.parquet")
    confident = [w for w in windows if not w.get("low_confidence")]
    per_recording = friction[(friction["level"] == "recording")
                             & (friction["recording"] == "trip-in-noisy")]
    assert per_recording["n"].sum() == len(confident)
    slack_off = [w["mu"] for w in confident if w["operation"] == "slack_off"]
    row = per_recording.set_index("operation").loc["slack_off"]
    assert row["mu_mean"] == pytest.approx(sum(slack_off) / len(slack_off))
    states = pd.read_parquet(summary / "states.parquet")
    assert states[states["level"] == "well"]["share"].sum() == pytest.approx(1.0)
    sections = pd.read_parquet(summary / "sections.parquet")
    assert set(sections["kind"]) == {"cased", "open"}
    page = (tmp_path / "out" / "summary.html").read_text()
    assert "4 recordings, 2 failed" in page and "replay not found" in page


def test_cli_batch_on_its_own_local_cluster(broken: Path, tmp_path: Path,
                                            capsys: pytest.CaptureFixture[str]) -> None:
    code = main(["batch", str(SHORT), str(broken), "--config", str(CONFIG),
                 "--out", str(tmp_path / "cli"), "--workers", "2"])
    out, err = capsys.readouterr()
    assert code == 1  # one failed
    assert "1/2 recordings replayed, 1 FAILED" in out
    assert f"{broken}: not an MCAP file" in out
    assert "[2/2]" in err and "trip-in-noisy.mcap: 965 messages" in err  # plain progress lines
    assert topic_counts(tmp_path / "cli" / "recordings" / "trip-in-noisy.mcap")[
        "/tdmon/raw"] == 965
    assert (tmp_path / "cli" / "summary.html").is_file()


def test_cli_batch_user_mistakes(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    assert main(["batch", str(SHORT), "--out", str(tmp_path), "--config",
                 str(tmp_path / "nope.toml")]) == 2
    assert "nope.toml: --config: no such file" in capsys.readouterr().err
    assert main(["batch", str(SHORT), "--out", str(tmp_path), "--workers", "0"]) == 2
    assert "--workers" in capsys.readouterr().err


def test_the_cap_holds_for_a_blas_the_replay_loads_later() -> None:
    """scipy carries its own OpenBLAS, loaded when the replay first needs scipy (lazily): the
    task's cap must cover it too (a fresh process whose BLAS would start at 2 threads)."""
    import os
    import subprocess
    import sys

    code = ("from tdmon.replay.batch import blas_capped\n"
            "with blas_capped() as most:\n"
            "    import scipy.optimize\n"
            "    print(most())\n")
    env = {**os.environ, "OPENBLAS_NUM_THREADS": "2"}
    out = subprocess.run([sys.executable, "-c", code], env=env, capture_output=True, text=True,
                         check=True, timeout=120)
    assert out.stdout.split() == ["1"], out.stderr


def _worker_environ() -> dict[str, str | None]:
    import os

    return {key: os.environ.get(key) for key in ("MALLOC_TRIM_THRESHOLD_", "OMP_NUM_THREADS")}


def test_the_local_cluster_leaves_glibc_malloc_to_tune_itself() -> None:
    """Dask's nanny sets MALLOC_TRIM_THRESHOLD_ in its workers by default (and in this
    process's environment, which the workers inherit: the module's cluster above has left it
    here), which made a replay cost up to 1.39 x its CPU time in a plain process; the batch's
    own cluster leaves it out, keeps the nanny's other settings (one OpenMP thread) and puts
    back this process's environment."""
    import os

    import dask
    from distributed import Client

    from tdmon.replay.batch import local_cluster

    assert "MALLOC_TRIM_THRESHOLD_" in dask.config.get("distributed.nanny.pre-spawn-environ")
    before = os.environ.get("MALLOC_TRIM_THRESHOLD_")
    with local_cluster(1) as cluster, Client(cluster) as client:
        (environ,) = client.run(_worker_environ).values()
    assert environ == {"MALLOC_TRIM_THRESHOLD_": None, "OMP_NUM_THREADS": "1"}
    assert os.environ.get("MALLOC_TRIM_THRESHOLD_") == before
    assert "MALLOC_TRIM_THRESHOLD_" in dask.config.get("distributed.nanny.pre-spawn-environ")
