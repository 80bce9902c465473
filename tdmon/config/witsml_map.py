"""The curve map of ``tdmon import witsml --map``: which WITSML curve feeds which channel.

A small TOML file: an optional topic ``prefix`` and one ``[curves.<channel>]`` table per
channel whose curve the default table (docs/witsml.md) does not find or finds wrongly, with the
curve's ``mnemonic`` and optionally the ``unit`` its numbers are in (replacing the curve's
``uom``, e.g. when it says ``unitless``)::

    prefix = "rig/F4"

    [curves.hookload]
    mnemonic = "HKLD"
    unit = "kN"
"""

from __future__ import annotations

from pathlib import Path

from pydantic import Field, field_validator

from tdmon.channels import CHANNEL_UNITS
from tdmon.config.common import StrictModel, load_model

__all__ = ["CurveMapConfig", "CurveSpec", "load_curve_map"]


class CurveSpec(StrictModel):
    """The curve feeding one channel (``unit``: its numbers' unit, default the curve's uom)."""

    mnemonic: str = Field(min_length=1)
    unit: str | None = Field(default=None, min_length=1)


class CurveMapConfig(StrictModel):
    """``prefix`` and ``[curves.<channel>]`` tables."""

    prefix: str | None = None
    curves: dict[str, CurveSpec] = Field(default_factory=dict)

    @field_validator("curves")
    @classmethod
    def _known(cls, curves: dict[str, CurveSpec]) -> dict[str, CurveSpec]:
        for name in curves:
            if name not in CHANNEL_UNITS:
                raise ValueError(f"unknown channel '{name}' (one of {', '.join(CHANNEL_UNITS)})")
        return curves

    def overrides(self) -> dict[str, tuple[str, str | None]]:
        """channel -> (mnemonic, unit or None), as :func:`tdmon.ingest.witsml.resolve_curves`
        takes them."""
        return {channel: (spec.mnemonic, spec.unit) for channel, spec in self.curves.items()}


def load_curve_map(path: str | Path) -> CurveMapConfig:
    """Read and validate a curve map.

    Raises
    ------
    ConfigError
        Missing file, not TOML, unknown channel or key; names the key and the reason.
    """
    return load_model(CurveMapConfig, path)
