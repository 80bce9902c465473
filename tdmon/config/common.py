"""Shared pieces of the TOML configuration models: quantity fields, the prefix rule, and the one
reader of every TOML file (:func:`load_model`) with its one error mapping."""

from __future__ import annotations

import tomllib
from collections.abc import Callable
from pathlib import Path
from typing import Annotated, Any, TypeVar

from pydantic import BaseModel, BeforeValidator, ConfigDict, ValidationError

from tdmon.errors import ConfigError
from tdmon.units import parse_quantity

GRAVITY = 9.80665  # [m/s^2], standard gravity (pound-force per foot is a weight per length)


class StrictModel(BaseModel):
    """Base of every configuration table: unknown keys are errors, models are immutable."""

    model_config = ConfigDict(extra="forbid", frozen=True)


def _converter(target: str) -> Callable[[Any], float]:
    """A function reading a number in ``target`` or a string with a unit, to ``target``."""

    def convert(value: Any) -> float:
        if not isinstance(value, (int, float, str)) or isinstance(value, bool):
            raise ValueError(f"expected a number in {target} or a string with a unit")
        number = parse_quantity(value, target)
        if number != number or number in (float("inf"), float("-inf")):
            raise ValueError("must be a finite number")
        return number

    return convert


def quantity(target: str) -> BeforeValidator:
    """A pydantic validator reading a number in ``target`` or a string with a unit (such as
    ``"3 min"``) into a finite number in ``target``: ``Annotated[float, quantity("s")]``."""
    return BeforeValidator(_converter(target))


def _weight_per_length(value: Any) -> float:
    """A weight per length in N/m; a mass per length such as "29 lb/ft" is multiplied by g."""
    try:
        return _converter("N/m")(value)
    except ValueError as as_force:
        try:
            return _converter("kg/m")(value) * GRAVITY
        except ValueError:
            raise as_force from None


Length = Annotated[float, quantity("m")]
Diameter = Annotated[float, quantity("m")]
Force = Annotated[float, quantity("N")]
Moment = Annotated[float, quantity("N*m")]
Pressure = Annotated[float, quantity("Pa")]
Density = Annotated[float, quantity("kg/m^3")]
WeightPerLength = Annotated[float, BeforeValidator(_weight_per_length)]
Dimensionless = Annotated[float, quantity("dimensionless")]

ModelT = TypeVar("ModelT", bound=BaseModel)


def _dotted(location: tuple[int | str, ...]) -> str:
    parts: list[str] = []
    for item in location:
        if isinstance(item, int):
            parts.append(f"[{item}]")
        else:
            parts.append(("." if parts else "") + item)
    return "".join(parts)


class CrossFieldError(ValueError):
    """A check across sections, raised by a model validator for the dotted ``key`` it names
    (pydantic places a model validator's error at the model, not at the key at fault)."""

    def __init__(self, key: str, reason: str) -> None:
        super().__init__(reason)
        self.key = key


def validation_to_config_error(path: Path | str, error: ValidationError) -> ConfigError:
    """The first validation problem as a ConfigError naming the file, the key and the reason."""
    first = error.errors()[0]
    reason = first["msg"]
    reason = reason.removeprefix("Value error, ")
    if first["type"] == "missing":
        reason = "missing key"
    elif first["type"] == "extra_forbidden":
        reason = "unknown key"
    loc = tuple(first["loc"])
    cause = first.get("ctx", {}).get("error")
    if isinstance(cause, CrossFieldError):
        loc = (*loc, *cause.key.split("."))
    more = len(error.errors()) - 1
    if more:
        reason += f" (and {more} more problem{'s' if more > 1 else ''})"
    return ConfigError(str(path), _dotted(loc), reason)


def read_toml(path: Path | str) -> dict[str, Any]:
    """Read a TOML file, translating missing files and syntax errors into ConfigError."""
    path = Path(path)
    try:
        with path.open("rb") as handle:
            return tomllib.load(handle)
    except FileNotFoundError as exc:
        raise ConfigError(str(path), "", "no such file") from exc
    except IsADirectoryError as exc:
        raise ConfigError(str(path), "", "is a folder, not a TOML file") from exc
    except tomllib.TOMLDecodeError as exc:
        raise ConfigError(str(path), "", f"not valid TOML: {exc}") from exc
    except (OSError, UnicodeDecodeError) as exc:
        raise ConfigError(str(path), "", f"cannot be read: {exc}") from exc


def validate_model(
    model: type[ModelT], data: dict[str, Any], path: Path | str,
    context: dict[str, Any] | None = None,
) -> ModelT:
    """Validate already-parsed TOML ``data`` from the file ``path`` against ``model``.

    Raises
    ------
    ConfigError
        The first problem, naming the file, the dotted key and the reason.
    """
    try:
        return model.model_validate(data, context=context)
    except ValidationError as exc:
        raise validation_to_config_error(path, exc) from exc


def load_model(
    model: type[ModelT], path: Path | str, context: dict[str, Any] | None = None
) -> ModelT:
    """Read the TOML file at ``path`` and validate it against ``model``: every TOML file of
    tdmon is read here, so that every mistake is reported the same way.

    Raises
    ------
    ConfigError
        The file is missing, not TOML, or invalid; the message names file, key and reason.
    """
    return validate_model(model, read_toml(path), path, context)


__all__ = [
    "Density",
    "Diameter",
    "Dimensionless",
    "Force",
    "Length",
    "Moment",
    "Pressure",
    "StrictModel",
    "WeightPerLength",
    "load_model",
    "quantity",
    "read_toml",
    "validate_model",
    "validation_to_config_error",
]
