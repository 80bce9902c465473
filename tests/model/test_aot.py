"""The ahead-of-time kernels against numba's JIT: the same numbers bit for bit for every model
call, the JIT when no build of the current source exists (and why, logged), and
`tdmon model warmup` without a compiler."""

from __future__ import annotations

import logging
from collections.abc import Callable, Iterator
from pathlib import Path

import numpy as np
import pytest

from tdmon.cli import main
from tdmon.errors import ModelError
from tdmon.model import aot, kernels
from tdmon.model.broomstick import broomstick_from_model
from tdmon.model.torque_drag import WellModel
from tdmon.model.well import Well


@pytest.fixture
def kernels_env(monkeypatch: pytest.MonkeyPatch) -> Iterator[Callable[..., None]]:
    """Set TDMON_KERNELS and the cache folder; the loaded choice is forgotten before and after."""

    def choose(mode: str | None = None, cache: Path | None = None) -> None:
        if mode is not None:
            monkeypatch.setenv(kernels.ENVIRONMENT, mode)
        if cache is not None:
            monkeypatch.setenv("XDG_CACHE_HOME", str(cache))
        kernels.forget()

    yield choose
    monkeypatch.undo()
    kernels.forget()


def _everything(model: WellModel, method: str) -> list[np.ndarray]:
    """Every number the model's calls return, flattened, one array per call."""
    cases = np.stack([model.friction(mu) for mu in (0.0, 0.17, 0.41)])
    cases[1, 40:90] = 0.6
    out: list[np.ndarray] = []
    for depth in (350.0, 1777.7, 3000.0):
        for operation, extra in (("pick_up", {}), ("slack_off", {}), ("rotating", {}),
                                 ("on_bottom", {"wob": 9e4, "bit_torque": 3e3}),
                                 ("pick_up", {"psi": 0.3})):
            out.append(np.array(model.evaluate(operation, depth, 0.23, method=method, **extra)))
            out.append(np.concatenate(model.evaluate_cases(operation, depth, cases,
                                                           method=method, **extra)))
        for index in (0, 1):
            value, gradient = model.evaluate_gradient("rotating", depth, cases[1],
                                                      quantity_index=index, method=method)
            out.append(np.append(gradient, value))
        loads = model.loads(depth, None, method=method)
        out.extend([loads.md, *loads.axial_force.values(), *loads.torque.values()])
    broom = broomstick_from_model(model, [500.0, 2000.0, 3000.0], [0.1, 0.3], method=method)
    out.extend([*broom.hookload.values(), *broom.surface_torque.values()])
    return out


@pytest.mark.parametrize("method", ["soft-string", "aadnoy"])
def test_ahead_of_time_and_jit_give_the_same_numbers(
        three_d: Well, example_71: Well, method: str,
        kernels_env: Callable[..., None]) -> None:
    for well in (three_d, example_71):
        kernels_env("aot")
        ahead = WellModel(well)
        kernels_env("jit")
        jit = WellModel(well)
        assert (ahead.kernels.kind, jit.kernels.kind) == ("aot", "jit")
        assert np.array_equal(ahead.kernel_well.real, jit.kernel_well.real)
        assert np.array_equal(ahead.kernel_well.integer, jit.kernel_well.integer)
        for got, expected in zip(_everything(ahead, method), _everything(jit, method),
                                 strict=True):
            assert got.tolist() == expected.tolist()  # bit for bit


def test_without_a_current_build_the_jit_serves_and_says_why(
        tmp_path: Path, kernels_env: Callable[..., None],
        caplog: pytest.LogCaptureFixture) -> None:
    kernels_env("auto", tmp_path)
    assert not kernels.aot_path().exists()
    with caplog.at_level(logging.INFO, logger="tdmon.model.kernels"):
        loaded = kernels.load()
    assert loaded.kind == "jit"
    assert "numba's JIT" in caplog.text and str(kernels.aot_path()) in caplog.text
    kernels_env("aot")
    with pytest.raises(ModelError, match="tdmon model warmup"):
        kernels.load()
    kernels_env("fast")
    with pytest.raises(ModelError, match="TDMON_KERNELS='fast'"):
        kernels.load()


def test_the_build_key_follows_the_kernels_source(
        tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    real = kernels.build_key()
    assert kernels.module_name() in kernels.aot_path().name
    sources = []
    for source in kernels._SOURCES:
        copy = tmp_path / source.name
        copy.write_bytes(source.read_bytes())
        sources.append(copy)
    monkeypatch.setattr(kernels, "_SOURCES", tuple(sources))
    try:
        kernels.build_key.cache_clear()
        same = kernels.build_key()
        sources[0].write_text(sources[0].read_text() + "\n# a change\n")
        kernels.build_key.cache_clear()
        changed = kernels.build_key()
    finally:
        monkeypatch.undo()
        kernels.build_key.cache_clear()
    assert same == real and changed != real


def test_warmup_without_a_compiler_uses_the_jit_with_a_note(
        tmp_path: Path, kernels_env: Callable[..., None], monkeypatch: pytest.MonkeyPatch,
        capsys: pytest.CaptureFixture[str]) -> None:
    def no_compiler(destination: Path | None = None) -> tuple[Path, float]:
        raise OSError("command 'gcc' failed: No such file or directory")

    kernels_env("auto", tmp_path / "cache")
    monkeypatch.setattr(aot, "build", no_compiler)
    monkeypatch.setenv("PATH", str(tmp_path))  # no compiler on it
    monkeypatch.delenv("CC", raising=False)
    assert main(["model", "warmup"]) == 0
    printed = capsys.readouterr().out.strip().splitlines()
    assert len(printed) == 1
    assert printed[0].startswith("model kernels: no ahead-of-time build (no C compiler found);")
    assert "numba's JIT compiled them" in printed[0]
    assert kernels.load().kind == "jit"
    kernels_env("aot")
    assert main(["model", "warmup"]) == 2  # asked for the ahead-of-time kernels: an error
    assert "TDMON_KERNELS=aot" in capsys.readouterr().err


def test_the_processor_level_needs_every_flag_of_it_and_of_the_levels_below() -> None:
    v2 = {"cx16", "lahf_lm", "popcnt", "sse4_1", "sse4_2", "ssse3"}
    v3 = {"avx", "avx2", "bmi1", "bmi2", "f16c", "fma", "movbe", "xsave", "abm"}
    v4 = {"avx512f", "avx512bw", "avx512cd", "avx512dq", "avx512vl"}
    assert kernels.x86_level({"fpu", "sse2"}) == ""
    assert kernels.x86_level(v2) == "x86-64-v2"
    assert kernels.x86_level(v2 | v3 | {"sha"}) == "x86-64-v3"
    assert kernels.x86_level(v2 | v3 | v4) == "x86-64-v4"
    assert kernels.x86_level((v2 | v3 | v4) - {"fma"}) == "x86-64-v2"  # no AVX2 level: no v4
    assert kernels.x86_level(v3 | v4) == ""
