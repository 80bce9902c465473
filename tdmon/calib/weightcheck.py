"""Weight alarms: the learnt block weight against the configured one, and hangs against the
model's string weight.

Static hangs keep part of the last pull's or run's drag locked in, so one odd hang is not news:
the weight check alarms when :data:`ODD_HANGS` hangs in a row are off by more than the
tolerance, once, and again only after the weights have agreed in between
(docs/back-calculation.md, "Block weight and weight check"). The alarm speaks in kN and % of
the string's weight; what the difference means (fluid inside, mud density, mass per metre) is
the joint estimate's weight-mismatch alarm (`tdmon.calib.mismatch`), which separates it from
friction first.
"""

from __future__ import annotations

import math

from tdmon.calib.alarms import Alarm
from tdmon.calib.blockweight import BuoyancyCheck, buoyancy_check
from tdmon.calib.windows import Window
from tdmon.errors import FitError, ModelError
from tdmon.model.torque_drag import WellModel
from tdmon.vocabulary import AlarmKind, Operation, Severity

__all__ = ["ODD_HANGS", "block_weight_alarm", "weight_check"]

#: consecutive hangs whose weight is off that raise the weight-check alarm [-]
ODD_HANGS = 3
#: a hang outside these times the modelled weight is no weight error a fluid or a tally can
#: make: the bit depth (or block weight) is wrong, e.g. depth tracking reset to 0 [-]
PLAUSIBLE_RATIO = (0.5, 2.0)


def block_weight_alarm(t: float, block: tuple[float, float], offset: tuple[float, float],
                       empty: tuple[float, float], configured: float, tolerance: float,
                       separated: bool = True) -> Alarm | None:
    """Alarm when what the joint estimate learnt of the travelling equipment differs from the
    well file's block weight by more than ``tolerance`` and by more than twice its spread.

    Parameters
    ----------
    t : [s]
    block : block weight as the sensor weighs it, its zero offset aside, and its standard
        deviation [N] (the joint estimate, :mod:`tdmon.calib.joint`)
    offset : the sensor's zero offset and its standard deviation [N]
    empty : what an empty, still block reads (block weight plus offset) and its standard
        deviation [N]: in-slips readings pin it down even when they cannot tell the two apart
    configured : the well file's block weight, as the sensor would weigh it [N] (0: none
        given, no alarm)
    tolerance : relative deviation that is reported [-]
    separated : whether the data tell the block weight from the offset (a moving block in
        slips, a string weight known from elsewhere); if not, only what the empty block reads
        is judged

    Returns
    -------
    The alarm naming the block weight when the block weight alone stands out; naming both
    causes when only what the empty block reads does (the block weight or the sensor's zero
    is off, and the data cannot say which).
    """
    if configured <= 0:
        return None
    limit = tolerance * configured

    def stands_out(value: float, std: float, reference: float) -> bool:
        return abs(value - reference) > limit and abs(value - reference) > 2 * std

    if separated and stands_out(*block, configured):
        return Alarm(t, AlarmKind.BLOCK_WEIGHT, Severity.INFO,
                     f"block weight {block[0] / 1e3:.0f} ± {block[1] / 1e3:.0f} kN (learnt with "
                     f"the sensor's zero offset and the string weight) differs from the "
                     f"configured {configured / 1e3:.0f} kN", block[0], configured)
    if stands_out(*empty, configured):
        return Alarm(t, AlarmKind.BLOCK_WEIGHT, Severity.INFO,
                     f"an empty block reads {empty[0] / 1e3:.0f} kN, the configured block "
                     f"weight is {configured / 1e3:.0f} kN: the block weight or the hook-load "
                     f"sensor's zero is off by {(empty[0] - configured) / 1e3:+.0f} kN (the "
                     f"zero offset is estimated at {offset[0] / 1e3:+.0f} ± "
                     f"{offset[1] / 1e3:.0f} kN)", empty[0], configured)
    return None


def weight_check(model: WellModel, air_model: WellModel, window: Window, block_weight: float,
                 odd: int, tolerance: float
                 ) -> tuple[BuoyancyCheck, int, Alarm | None] | None:
    """Check one static (or circulating, or rotating off bottom) window's string weight.

    Parameters
    ----------
    model : the prepared well
    air_model : the same well without fluid
    window : a usable window without axial friction
    block_weight : block weight (learnt in slips, else configured) [N]
    odd : hangs in a row whose weight was off before this one [-]
    tolerance : relative deviation of the weight ratio that counts as off [-]

    Returns
    -------
    (check, odd hangs in a row now, alarm or None), or None when the model has no weight here
    """
    try:
        modelled = model.evaluate(Operation.STATIC, window.bit_depth, 0.0)[0]
        in_air = air_model.evaluate(Operation.STATIC, window.bit_depth, 0.0)[0]
        check = buoyancy_check(window.hookload, block_weight, modelled, in_air,
                               model.well.block_weight)
    except (FitError, ModelError):
        return None
    odd = odd + 1 if abs(check.ratio - 1.0) > tolerance else 0
    if odd != ODD_HANGS or not math.isfinite(check.ratio):
        return check, odd, None
    difference = check.measured_weight - check.modelled_weight
    word = "lighter" if difference < 0 else "heavier"
    if not PLAUSIBLE_RATIO[0] <= check.ratio <= PLAUSIBLE_RATIO[1]:
        return check, odd, Alarm(
            window.t_end, AlarmKind.WEIGHT_CHECK, Severity.WARNING,
            f"hook load shows {check.measured_weight / 1e3:.0f} kN of string below the block, "
            f"the model {check.modelled_weight / 1e3:.0f} kN for a bit at "
            f"{window.bit_depth:.0f} m, for three hangs in a row: check the bit-depth "
            "tracking and the block weight", check.measured_weight, check.modelled_weight)
    return check, odd, Alarm(
        window.t_end, AlarmKind.WEIGHT_CHECK, Severity.INFO,
        f"{window.state} string at {window.bit_depth:.0f} m hangs {abs(difference) / 1e3:.0f} kN "
        f"({100 * abs(check.ratio - 1.0):.1f} %) {word} than modelled for three hangs in a row "
        "(a hang after a pull or a run keeps some drag locked in)",
        check.measured_weight, check.modelled_weight)
