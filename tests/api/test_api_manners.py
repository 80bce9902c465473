"""What a user meets first at the prompt (issue 33, item 8): friction checked as the command
line checks it, short reprs, a ``dir(tdmon)`` that shows the API."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

import tdmon
from tdmon.errors import ModelError

REPO = Path(__file__).resolve().parents[2]
WELL = REPO / "config" / "wells" / "aadnoy-example-7-1.toml"


@pytest.fixture(scope="module")
def well() -> tdmon.WellFile:
    return tdmon.load_well(WELL)


@pytest.mark.parametrize(("mu", "reason"), [
    (5, "mu: friction factor 5 is outside 0-1"),
    (-0.1, "mu: friction factor -0.1 is outside 0-1"),
    (float("nan"), "mu: friction factor nan is outside 0-1"),
    (True, "mu: expected a friction factor"),
    ("slippery", "mu: 'slippery' is not a number"),
    (["a", "b"], "mu: expected friction factors"),
])
def test_friction_outside_the_command_lines_range_is_refused(
        well: tdmon.WellFile, mu: object, reason: str) -> None:
    with pytest.raises(ModelError, match=reason.replace("(", r"\(")):
        tdmon.evaluate_loads(well, 3000.0, mu=mu)  # type: ignore[arg-type]


def test_one_element_outside_the_range_is_named(well: tdmon.WellFile) -> None:
    friction = np.full(well.friction.size, 0.2)
    friction[7] = 1.5
    with pytest.raises(ModelError, match=r"friction factor 1.5 \(element 7\) is outside 0-1"):
        tdmon.evaluate_loads(well, 3000.0, mu=friction)


def test_friction_in_range_gives_the_same_loads_in_every_spelling(well: tdmon.WellFile) -> None:
    number = tdmon.evaluate_loads(well, 3000.0, mu=0.2, operation="pick_up")
    text = tdmon.evaluate_loads(well, 3000.0, mu="0.2", operation="pick_up")
    array = tdmon.evaluate_loads(well, 3000.0, mu=np.full(well.friction.size, 0.2),
                                 operation="pick_up")
    hookload = number["hookload_N"].iloc[0]
    assert text["hookload_N"].iloc[0] == hookload == array["hookload_N"].iloc[0]
    # the bounds themselves are friction factors
    zero, one = (tdmon.evaluate_loads(well, 3000.0, mu=mu, operation="pick_up")
                 ["hookload_N"].iloc[0] for mu in (0, 1))
    assert zero < hookload < one


def test_a_well_file_repr_is_one_short_line(well: tdmon.WellFile) -> None:
    text = repr(well)
    assert len(text) < 200 and "\n" not in text
    assert text == (f"WellFile({str(WELL)!r}, name='Aadnoy Example 7.1', string 4223.6 m, "
                    "hole 4223.6 m, 424 elements, friction 0.15-0.15)")


def test_a_recording_repr_counts_its_messages_without_printing_frames() -> None:
    path = REPO / "replays" / "trip-in-noisy.mcap"
    recording = tdmon.read_recording(path, topics=["/truth/state"])
    text = repr(recording)
    assert len(text) < 400 and "\n" not in text
    assert text.startswith(f"Recording({str(path)!r}, messages: /tdmon/raw 965 (not read), ")
    assert text.endswith("/truth/state 19)")
    assert len(recording.other["/truth/state"]) == 19


def test_dir_shows_the_api_not_the_modules_helpers() -> None:
    import tdmon.model  # a subpackage loaded: still not part of dir()

    names = dir(tdmon)
    assert set(tdmon.__all__) <= set(names)
    public = [name for name in names if not name.startswith("_")]
    assert public == sorted(set(tdmon.__all__) - {"__version__"})
    assert "__version__" in names and "__file__" in names
