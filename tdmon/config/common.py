"""Shared pieces of the TOML configuration models: quantity fields, the prefix rule, and the one
reader of every TOML file (:func:`load_model`) with its one error mapping."""

from __future__ import annotations

import difflib
import re
import sys
import tomllib
from collections.abc import Callable
from pathlib import Path
from types import UnionType
from typing import Annotated, Any, Final, TypeVar, Union, get_args, get_origin

from pydantic import (
    AfterValidator,
    BaseModel,
    BeforeValidator,
    ConfigDict,
    ValidationError,
    ValidationInfo,
)

from tdmon.config.limits import MAX_DURATION, MAX_TOML_BYTES
from tdmon.errors import ConfigError
from tdmon.units import UnitError, examples, parse_quantity, split_quantity


class StrictModel(BaseModel):
    """Base of every configuration table: unknown keys are errors, models are immutable."""

    model_config = ConfigDict(extra="forbid", frozen=True)


#: Validation context key set by :func:`validate_model` (every file): a dimensional quantity
#: read from a file must carry its unit. Python callers building models pass SI floats.
UNITS_REQUIRED: Final = "units_required"

#: Friction factors above this are refused everywhere (files and command line): steel on steel
#: or on rock in drilling mud is 0.1-0.5 and back-calculated values rarely pass 0.6; above 1
#: a value is a typing mistake (a percentage, a doubled digit), not a friction factor.
MAX_FRICTION: Final = 1.0

# the unit an error message suggests for a target, as people write it on a rig
_EXAMPLE_UNITS: Final = {
    "N": "kN", "N*m": "kN*m", "Pa": "MPa", "m": "m", "s": "s", "m/s": "m/s", "rad/s": "rpm",
    "m**3/s": "L/min", "kg/m^3": "kg/m^3", "kg/m**3": "kg/m^3", "N/m": "kN/m", "degC": "degC",
}
_PLAIN_NUMBER = re.compile(r"[\d\s.+\-eE/]*")


def _is_dimensionless(target: str) -> bool:
    return target in ("dimensionless", "")


def unit_example(target: str) -> str:
    """A unit to suggest in an error message for a quantity in ``target``."""
    return _EXAMPLE_UNITS.get(target) or next(iter(examples(target)), target)


def refused_unit(error: UnitError, value: Any, target: str, key: str | None = None) -> str:
    """The reason a quantity's unit is refused, with the key written with a unit that works:
    ``unknown unit 'tonnez'; write e.g. block_weight = "40 kN"``.

    The example keeps the value's number (``"40 tonnez"`` -> ``"40 kN"``) with the unit
    :func:`unit_example` suggests for the target.
    """
    try:
        number = split_quantity(value)[0] if isinstance(value, str) else None
    except ValueError:
        number = None
    shown = "1" if number is None else f"{number:g}"
    return f"{error.reason}; write e.g. {key or 'key'} = \"{shown} {unit_example(target)}\""


def missing_unit(value: Any, target: str, key: str | None = None) -> str | None:
    """The reason a plain ``value`` (a number, or a text without a unit) for a quantity in
    ``target`` is refused, or None when it has a unit or ``target`` is dimensionless.

    A plain number was once read as SI, so ``block_weight = 655`` meant as kN gave hook loads
    654 kN low; a file has to say which unit it means.
    """
    if _is_dimensionless(target) or isinstance(value, bool):
        return None
    if isinstance(value, str):
        if not _PLAIN_NUMBER.fullmatch(value):
            return None
        shown = value.strip()
    elif isinstance(value, (int, float)):
        shown = f"{value:g}"
    else:
        return None
    name = key or "key"
    return (f"{shown} has no unit; write the unit, e.g. {name} = "
            f"\"{shown} {unit_example(target)}\"")


def _converter(target: str) -> Callable[[Any, ValidationInfo | None], float]:
    """A function reading a number in ``target`` or a string with a unit, to ``target``; with
    the :data:`UNITS_REQUIRED` context (a file) a dimensional value needs its unit."""

    def convert(value: Any, info: ValidationInfo | None = None) -> float:
        if not isinstance(value, (int, float, str)) or isinstance(value, bool):
            raise ValueError(f"expected a number in {target} or a string with a unit")
        if info is not None and (info.context or {}).get(UNITS_REQUIRED):
            reason = missing_unit(value, target, info.field_name)
            if reason is not None:
                raise ValueError(reason)
        try:
            number = parse_quantity(value, target)
        except UnitError as exc:
            key = info.field_name if info is not None else None
            raise ValueError(refused_unit(exc, value, target, key)) from None
        if number != number or number in (float("inf"), float("-inf")):
            raise ValueError("must be a finite number")
        return number

    return convert


def quantity(target: str) -> BeforeValidator:
    """A pydantic validator reading a string with a unit (such as ``"3 min"``) into a finite
    number in ``target``: ``Annotated[float, quantity("s")]``. A plain number is accepted from
    Python (SI) and, in a file, only for a dimensionless ``target``."""
    convert = _converter(target)

    def validate(value: Any, info: ValidationInfo) -> float:
        return convert(value, info)

    return BeforeValidator(validate)


def _friction_factor(value: Any) -> float:
    if isinstance(value, bool) or not isinstance(value, (int, float, str)):
        raise ValueError("expected a friction factor (a number)")
    number = parse_quantity(value, "dimensionless")
    if not 0.0 <= number <= MAX_FRICTION:
        raise ValueError(f"friction factor {number:g} is outside 0-{MAX_FRICTION:g}")
    return number


def check_friction(value: float) -> float:
    """``value`` if it is a friction factor (0 to :data:`MAX_FRICTION`), else ValueError: the
    one rule of well files, daemon files and the command line."""
    return _friction_factor(value)


def _bounded_duration(value: float) -> float:
    if value > MAX_DURATION:
        raise ValueError(f"{value:g} s is longer than a week ({MAX_DURATION:g} s), the longest "
                         "duration accepted (a longer one is a typing mistake)")
    return value


#: A duration [s] with its unit, at most :data:`~tdmon.config.limits.MAX_DURATION`
Duration = Annotated[float, quantity("s"), AfterValidator(_bounded_duration)]
Length = Annotated[float, quantity("m")]
Diameter = Annotated[float, quantity("m")]
#: A force; a mass (``"40 t"``) is its weight under standard gravity (tdmon.units.GRAVITY)
Force = Annotated[float, quantity("N")]
Moment = Annotated[float, quantity("N*m")]
Pressure = Annotated[float, quantity("Pa")]
Density = Annotated[float, quantity("kg/m^3")]
#: A weight per length; a mass per length (``"19.5 lb/ft"``, ``"43 kg/m"``) is multiplied by g
WeightPerLength = Annotated[float, quantity("N/m")]
Dimensionless = Annotated[float, quantity("dimensionless")]
FrictionFactor = Annotated[float, BeforeValidator(_friction_factor)]

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


# pydantic's tags of union members and validated models in an error location, e.g. "bool",
# "MqttConfig", "function-after[_one_password(), MqttConfig]": not keys of the file
_UNION_TAG = re.compile(r".*[\[(].*|[A-Z][A-Za-z0-9]*|bool|int|float|str")


def _relevant(errors: list[Any]) -> list[Any]:
    """The errors worth reporting: a table given for ``bool | Table`` fails the bool member
    too, and that "Input should be a valid boolean" hides the table's real problem."""
    kept = [e for e in errors
            if not (e["type"].endswith("_type") and isinstance(e.get("input"), dict)
                    and any(isinstance(p, str) and _UNION_TAG.fullmatch(p) for p in e["loc"]))]
    return kept or errors


def _key_path(loc: tuple[Any, ...]) -> tuple[Any, ...]:
    return tuple(p for p in loc if not (isinstance(p, str) and _UNION_TAG.fullmatch(p)))


def _model_types(kind: Any) -> list[Any]:
    """The models (and containers) a field's annotation may hold, unwrapped."""
    origin = get_origin(kind)
    if origin is Annotated:
        return _model_types(get_args(kind)[0])
    if origin in (Union, UnionType):
        return [t for arg in get_args(kind) for t in _model_types(arg)]
    return [kind]


def _key_names(model: type[BaseModel] | None, path: tuple[Any, ...]) -> set[str]:
    """The keys the table at ``path`` (keys and list indices) of ``model`` accepts."""
    kinds: list[Any] = [model] if model is not None else []
    for part in path:
        following: list[Any] = []
        for kind in kinds:
            origin = get_origin(kind)
            if isinstance(kind, type) and issubclass(kind, BaseModel):
                fields = kind.model_fields
                field = fields.get(part) if isinstance(part, str) else None
                if field is None and isinstance(part, str):
                    field = next((f for f in fields.values() if f.alias == part), None)
                if field is not None:
                    following += _model_types(field.annotation)
            elif origin in (list, tuple) and isinstance(part, int):
                following += [t for arg in get_args(kind) if arg is not Ellipsis
                              for t in _model_types(arg)]
            elif origin is dict and isinstance(part, str):
                following += _model_types(get_args(kind)[1])
        kinds = following
    names: set[str] = set()
    for kind in kinds:
        if isinstance(kind, type) and issubclass(kind, BaseModel):
            names |= {f.alias or name for name, f in kind.model_fields.items()}
    return names


def _unknown_key(error: Any, errors: list[Any], model: type[BaseModel] | None
                 ) -> tuple[str, Any | None]:
    """The reason for an unknown key, with the close match among the table's keys, and the
    'missing key' error that match explains (None if none)."""
    loc = _key_path(error["loc"])
    name = str(loc[-1])
    missing = [e for e in errors if e["type"] == "missing"
               and len(_key_path(e["loc"])) == len(loc) and _key_path(e["loc"])[:-1] == loc[:-1]]
    candidates = _key_names(model, loc[:-1]) | {str(_key_path(e["loc"])[-1]) for e in missing}
    match = difflib.get_close_matches(name, sorted(candidates - {name}), n=1, cutoff=0.6)
    if not match:
        return f"unknown key '{name}'", None
    explained = next((e for e in missing if _key_path(e["loc"])[-1] == match[0]), None)
    return f"unknown key '{name}', did you mean '{match[0]}'?", explained


def validation_to_config_error(path: Path | str, error: ValidationError,
                               model: type[BaseModel] | None = None) -> ConfigError:
    """The first validation problem as a ConfigError naming the file, the key and the reason.

    An unknown key comes first when it is a misspelling (difflib's close match) of a key of its
    table, ``model``'s field names: ``unknown key 'colum', did you mean 'column'?``, and the
    'missing key' error of the key it stands for is not counted as another problem.
    """
    errors = _relevant(error.errors())
    first = errors[0]
    reason = first["msg"]
    reason = reason.removeprefix("Value error, ")
    if first["type"] == "missing":
        reason = "missing key"
    elif first["type"] == "extra_forbidden":
        reason = "unknown key"
    for candidate in errors:
        if candidate["type"] != "extra_forbidden":
            continue
        text, explained = _unknown_key(candidate, errors, model)
        if explained is not None or text.endswith("?") or candidate is first:
            first, reason = candidate, text
            errors = [e for e in errors if e is not explained]
            break
    loc = _key_path(first["loc"])
    cause = first.get("ctx", {}).get("error")
    if isinstance(cause, CrossFieldError):
        loc = (*loc, *cause.key.split("."))
    more = len(errors) - 1
    if more:
        reason += f" (and {more} more problem{'s' if more > 1 else ''})"
    return ConfigError(str(path), _dotted(loc), reason)


def read_toml(path: Path | str) -> dict[str, Any]:
    """Read a TOML file, translating missing files, syntax errors, a file over
    :data:`~tdmon.config.limits.MAX_TOML_BYTES` and nesting too deep for the parser into
    ConfigError."""
    path = Path(path)
    try:
        with path.open("rb") as handle:
            data = handle.read(MAX_TOML_BYTES + 1)
    except FileNotFoundError as exc:
        raise ConfigError(str(path), "", "no such file") from exc
    except IsADirectoryError as exc:
        raise ConfigError(str(path), "", "is a folder, not a TOML file") from exc
    except OSError as exc:
        raise ConfigError(str(path), "", f"cannot be read: {exc}") from exc
    if len(data) > MAX_TOML_BYTES:
        raise ConfigError(str(path), "", f"larger than {MAX_TOML_BYTES // 1024} KiB, the most "
                          "a TOML file of tdmon may hold (a long survey belongs in a CSV file: "
                          "[survey] file)")
    try:
        return tomllib.loads(data.decode("utf-8"))
    except tomllib.TOMLDecodeError as exc:
        raise ConfigError(str(path), "", f"not valid TOML: {exc}") from exc
    except UnicodeDecodeError as exc:
        raise ConfigError(str(path), "", f"cannot be read: {exc}") from exc
    except RecursionError:
        # tomllib parses nested arrays and tables recursively
        raise ConfigError(str(path), "", "not valid TOML: arrays or tables nested too deeply "
                          f"(more than Python's {sys.getrecursionlimit()} levels)") from None


def validate_model(
    model: type[ModelT], data: dict[str, Any], path: Path | str,
    context: dict[str, Any] | None = None,
) -> ModelT:
    """Validate already-parsed TOML ``data`` from the file ``path`` against ``model``
    (dimensional quantities need their unit: see :data:`UNITS_REQUIRED`).

    Raises
    ------
    ConfigError
        The first problem, naming the file, the dotted key and the reason.
    """
    try:
        return model.model_validate(data, context={UNITS_REQUIRED: True, **(context or {})})
    except ValidationError as exc:
        raise validation_to_config_error(path, exc, model) from exc


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
    "MAX_FRICTION",
    "UNITS_REQUIRED",
    "Density",
    "Diameter",
    "Dimensionless",
    "Duration",
    "Force",
    "FrictionFactor",
    "Length",
    "Moment",
    "Pressure",
    "StrictModel",
    "WeightPerLength",
    "check_friction",
    "load_model",
    "missing_unit",
    "quantity",
    "read_toml",
    "refused_unit",
    "unit_example",
    "validate_model",
    "validation_to_config_error",
]
