"""``tdmon lab fit`` on the thesis's tribometer data (Table 14): the JSON against the calib
functions and docs/lab-fit.md, the ranked text table with its verdicts, Figure 15, and the
one-line errors for bad files."""

from __future__ import annotations

import json
from pathlib import Path

import pytest

from tdmon.calib.labfit import fit_friction_models, temperature_averages
from tdmon.cli import main
from tdmon.ingest.lab import read_tribometer_csv

DATA = Path(__file__).resolve().parents[2] / "data" / "lab" / "glydril-tribometer.csv"

# Table 14's printed "Average" row (not the means of the printed runs at 30 and 40 degC)
PRINTED_AVERAGES = "temperature_C,friction_coefficient\n30,0.279\n40,0.287\n50,0.283\n" \
                   "60,0.3185\n70,0.306\n"
KEYS = {"model", "family", "data", "coefficients", "standard_errors", "confidence_intervals",
        "p_values", "n", "n_parameters", "r", "r2", "adj_r2", "stderr", "aicc", "loo_rmse",
        "temperature_significant", "verdict", "rank"}


def _reject_nan(name: str) -> None:
    raise AssertionError(f"JSON holds {name}")


def run_json(capsys: pytest.CaptureFixture[str], *argv: str) -> dict:
    assert main(["lab", "fit", *argv, "--json"]) == 0
    return json.loads(capsys.readouterr().out, parse_constant=_reject_nan)


def pick(document: dict, model: str, data: str) -> dict:
    (fit,) = [f for f in document["fits"] if f["model"] == model and f["data"] == data]
    return fit


def test_json_has_raw_and_average_fits_of_every_model(capsys):
    document = run_json(capsys, str(DATA))
    assert document["runs"] == 34 and document["failed_runs"] == 1
    assert document["averages"]["temperature_C"] == [30.0, 40.0, 50.0, 60.0, 70.0]
    assert document["averages"]["runs"] == [7, 7, 7, 6, 7]
    for data in ("raw", "averages"):
        fits = [f for f in document["fits"] if f["data"] == data]
        assert {f["model"] for f in fits} == {"linear", "poly-2", "poly-3", "power",
                                              "exponential", "saturation-growth"}
        assert sorted(f["rank"] for f in fits) == list(range(1, 7))
        for fit in fits:
            assert set(fit) >= KEYS, KEYS - set(fit)


def test_json_equals_the_calib_functions(capsys):
    document = run_json(capsys, str(DATA))
    data = read_tribometer_csv(DATA)
    raw = fit_friction_models(data.temperature, data.friction, data="raw")
    levels, means, _ = temperature_averages(data.temperature, data.friction)
    averaged = fit_friction_models(levels, means, data="averages")
    expected = [json.loads(json.dumps(fit.to_dict())) for fit in raw + averaged]
    assert document["fits"] == expected


def test_raw_runs_show_no_significant_temperature_effect(capsys):
    """docs/lab-fit.md: on all 34 runs R^2 = 0.03 and the slope's 95 %
    interval includes zero."""
    linear = pick(run_json(capsys, str(DATA)), "linear", "raw")
    assert linear["n"] == 34
    assert linear["coefficients"]["a"] == pytest.approx(0.25561, abs=5e-5)
    assert linear["coefficients"]["b"] == pytest.approx(0.000785, abs=5e-6)
    assert linear["r2"] == pytest.approx(0.029, abs=0.001)
    low, high = linear["confidence_intervals"]["b"]
    assert low < 0.0 < high
    assert linear["standard_errors"]["b"] == pytest.approx(0.00080, abs=0.00002)
    assert linear["temperature_significant"] is False
    assert "NOT significant" in linear["verdict"]


def test_true_means_of_the_runs(capsys):
    linear = pick(run_json(capsys, str(DATA), "--models", "linear"), "linear", "averages")
    assert linear["n"] == 5
    assert linear["coefficients"]["a"] == pytest.approx(0.25494, abs=5e-5)
    assert linear["coefficients"]["b"] == pytest.approx(0.000808, abs=5e-6)
    assert linear["r2"] == pytest.approx(0.612, abs=0.001)


def test_printed_averages_reproduce_reference(tmp_path, capsys):
    """docs/lab-fit.md: with the printed averages the least-squares line is 0.25195 + 0.000855 T,
    R^2 0.643, adjusted 0.524, SE 0.0116; Table 16's polynomial statistics follow closely."""
    table = tmp_path / "table14-averages.csv"
    table.write_text(PRINTED_AVERAGES)
    document = run_json(capsys, str(table), "--averages", "--models", "linear,poly-2,poly-3")
    assert {f["data"] for f in document["fits"]} == {"averages"}
    linear = pick(document, "linear", "averages")
    assert linear["coefficients"]["a"] == pytest.approx(0.25195, abs=5e-6)
    assert linear["coefficients"]["b"] == pytest.approx(0.000855, abs=5e-7)
    assert linear["r2"] == pytest.approx(0.643, abs=0.0005)
    assert linear["adj_r2"] == pytest.approx(0.524, abs=0.0005)
    assert linear["stderr"] == pytest.approx(0.0116, abs=0.00005)
    assert linear["temperature_significant"] is False
    low, high = linear["confidence_intervals"]["b"]
    assert low < 0.0 < high
    # Table 16: standard errors 0.01164 / 0.01426 / 0.01651 (the refit agrees to ~1e-4)
    assert pick(document, "poly-2", "averages")["stderr"] == pytest.approx(0.01426, abs=1e-4)
    assert pick(document, "poly-3", "averages")["stderr"] == pytest.approx(0.01651, abs=2e-4)
    assert pick(document, "poly-3", "averages")["r2"] == pytest.approx(0.7572, abs=1e-4)
    assert linear["rank"] == 1


def test_text_is_a_ranked_table_with_intervals_and_verdicts(capsys):
    assert main(["lab", "fit", str(DATA), "--models", "linear,poly-2"]) == 0
    out = capsys.readouterr().out
    assert "34 runs, 1 failed run(s) dropped" in out
    assert "every run (n = 34)" in out and "per-temperature averages (n = 5)" in out
    assert "±" in out and "R^2" in out and "adj R^2" in out
    assert out.count("NOT significant") == 4
    assert "No fitted law shows a temperature effect distinguishable from zero" in out
    table = [line.split() for line in out.splitlines() if line.startswith("   1 ")]
    assert len(table) == 2  # one rank-1 row per data kind


def test_png_is_a_png(tmp_path, capsys):
    target = tmp_path / "new" / "figure15.png"  # the missing folder is created
    assert main(["lab", "fit", str(DATA), "--png", str(target), "--models",
                 "linear,poly-3"]) == 0
    assert target.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
    assert target.stat().st_size > 10_000
    out = capsys.readouterr().out
    assert str(target) in out
    # the figure comes with the numbers: the rank-1 linear fit's coefficients, as calib has them
    data = read_tribometer_csv(DATA)
    [linear] = [f for f in fit_friction_models(data.temperature, data.friction,
                                               ("linear", "poly-3"), data="raw")
                if f.model == "linear"]
    a, b = linear.coefficients["a"], linear.coefficients["b"]
    row = next(line for line in out.splitlines() if " linear " in line)
    assert f"a {a:.5g} ± " in row and f"b {b:.5g} ± " in row


def _one_line_error(capsys: pytest.CaptureFixture[str], *argv: str) -> str:
    assert main(list(argv)) == 2
    captured = capsys.readouterr()
    assert captured.out == ""
    lines = captured.err.strip().splitlines()
    assert len(lines) == 1, captured.err
    assert lines[0].startswith("tdmon: error: ")
    return lines[0]


@pytest.mark.parametrize(
    ("content", "message"),
    [
        ("test,temperature_C,friction_coefficient\n1,30,abc\n2,40,0.3\n",
         "data row 1: 'friction_coefficient' is not a number"),
        ("a,b\n1,2\n", "no 'temperature_C' column"),
        ("test,temperature_C,friction_coefficient\n1,30,\n", "no successful run"),
        ("test,temperature_C,friction_coefficient\n1,30,0.3\n2,30,0.4\n",
         "could be fitted"),
        (b"\x89PNG\r\n\x1a\n\x00\xff\xfe binary",
         "bad.csv: not a text file (not UTF-8), so not tribometer data: lab fit reads a CSV "
         "with columns test, temperature_C, friction_coefficient"),
        (b"test,temperature_C\x00,friction_coefficient\n", "not a text file"),
    ],
)
def test_bad_csv_is_one_line(tmp_path, capsys, content, message):
    path = tmp_path / "bad.csv"
    if isinstance(content, bytes):
        path.write_bytes(content)
    else:
        path.write_text(content)
    line = _one_line_error(capsys, "lab", "fit", str(path))
    assert message in line


def test_a_recording_is_named_for_what_it_is(capsys):
    # issue 33: it said "'utf-8' codec can't decode byte 0x89 in position 0"
    recording = DATA.parents[2] / "replays" / "trip-in-noisy.mcap"
    line = _one_line_error(capsys, "lab", "fit", str(recording))
    assert line == (f"tdmon: error: {recording}: an MCAP recording, not tribometer data: lab "
                    "fit reads a CSV with columns test, temperature_C, friction_coefficient "
                    "(docs/lab-fit.md); a recording goes to tdmon report or tdmon view")


def test_text_with_a_character_cut_at_the_sniffed_length_is_read(tmp_path, capsys):
    # the first 64 kB are looked at: a two-byte character across that edge is no mistake
    from tdmon.cli.lab import _SNIFF_BYTES

    header = "# données: ".encode()
    pad = _SNIFF_BYTES - 1 - len(header)
    path = tmp_path / "long-comment.csv"
    path.write_bytes(header + b"x" * pad + "é\n".encode() + DATA.read_bytes())
    assert path.read_bytes()[_SNIFF_BYTES - 1:_SNIFF_BYTES + 1] == "é".encode()
    assert run_json(capsys, str(path))["runs"] == 34


def test_missing_file_is_one_line(tmp_path, capsys):
    line = _one_line_error(capsys, "lab", "fit", str(tmp_path / "none.csv"))
    assert "none.csv" in line


def test_unknown_model_is_refused(capsys):
    with pytest.raises(SystemExit) as exit_info:
        main(["lab", "fit", str(DATA), "--models", "linear,cubic"])
    assert exit_info.value.code == 2
    assert "unknown model 'cubic'" in capsys.readouterr().err


def test_help_explains(capsys):
    with pytest.raises(SystemExit) as exit_info:
        main(["lab", "fit", "--help"])
    assert exit_info.value.code == 0
    out = capsys.readouterr().out
    assert "confidence" in out and "averages" in out and "Figure 15" in out
