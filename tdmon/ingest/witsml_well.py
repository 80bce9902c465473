"""A well file drafted from WITSML 1.4.1.1 trajectory, tubular, wbGeometry, rig and fluidsReport
objects.

The parsers (``parse_*``) read one object file's XML into frozen dataclasses, SI values from each
element's ``uom``; :func:`draft_well` writes the TOML text that :func:`tdmon.config.load_well`
reads, every dimensional value as a string with its unit. WITSML carries no friction factors and
often no block weight, fluid density, weight per length or tool-joint size: what could not be
read is listed at the top of the draft (and returned, for the command to print), with commented
suggestions. Values below zero (WITSML exports write ``-9999`` for "unknown") and zero yields
count as absent. See docs/witsml.md.
"""

from __future__ import annotations

import itertools
import math
import xml.etree.ElementTree as ET
from collections.abc import Iterable
from dataclasses import dataclass, field
from typing import IO, Final

from tdmon.errors import IngestError
from tdmon.ingest.witsml import OBJECT_KINDS, child_text, local_name, pint_unit
from tdmon.model.string import GRAVITY, weight_per_length
from tdmon.units import conversion

__all__ = [
    "NOMINAL_WEIGHTS",
    "GeometrySection",
    "Rig",
    "Station",
    "Trajectory",
    "Tubular",
    "TubularComponent",
    "WellDraft",
    "WellObjects",
    "WellboreGeometry",
    "draft_well",
    "read_objects",
]

#: API nominal weights [lb/ft] by (kind, OD [in], ID [in]): 5CT casing and tubing (couplings
#: included) and 5DP drill pipe (body only; tool joints add 5-10 %). Used when a component has
#: no ``wtPerLen`` and its size matches one within 0.01 in on the OD and 0.03 in on the ID.
NOMINAL_WEIGHTS: Final[tuple[tuple[str, float, float, float], ...]] = (
    ("tubing", 2.875, 2.441, 6.5), ("tubing", 3.5, 2.992, 9.3), ("tubing", 4.5, 3.958, 12.75),
    ("casing", 5.5, 4.892, 17.0), ("casing", 5.5, 4.778, 20.0), ("casing", 5.5, 4.670, 23.0),
    ("casing", 7.0, 6.366, 23.0), ("casing", 7.0, 6.276, 26.0), ("casing", 7.0, 6.184, 29.0),
    ("casing", 7.0, 6.094, 32.0), ("casing", 7.0, 6.004, 35.0), ("casing", 7.0, 5.920, 38.0),
    ("casing", 9.625, 8.835, 40.0), ("casing", 9.625, 8.755, 43.5),
    ("casing", 9.625, 8.681, 47.0), ("casing", 9.625, 8.535, 53.5),
    ("drill pipe", 3.5, 2.764, 13.3), ("drill pipe", 4.0, 3.340, 14.0),
    ("drill pipe", 5.0, 4.276, 19.5), ("drill pipe", 5.0, 4.000, 25.6),
    ("drill pipe", 5.5, 4.778, 21.9), ("drill pipe", 5.5, 4.670, 24.7),
    ("drill pipe", 6.625, 5.965, 25.2),
)

_INCH: Final = 0.0254


@dataclass(frozen=True)
class Station:
    """A survey station: md [m], inclination and azimuth [deg]."""

    md: float
    incl_deg: float
    azi_deg: float


@dataclass(frozen=True)
class Trajectory:
    uid: str
    name: str
    source: str
    stations: tuple[Station, ...]
    units: str  # the uoms read, e.g. "md m, incl rad, azi rad"


@dataclass(frozen=True)
class TubularComponent:
    """One ``tubularComponent``: length, od, id [m], weight [kg/m] (None: absent),
    connection OD [m] and yield stress [Pa] when given."""

    uid: str
    kind: str
    sequence: int
    length: float
    od: float
    id: float
    weight: float | None = None
    connection_od: float | None = None
    yield_strength: float | None = None


@dataclass(frozen=True)
class Tubular:
    """A ``tubular``: components from the bit up (ascending ``sequence``: 1 entered first)."""

    uid: str
    name: str
    source: str
    assembly: str
    created: str
    components: tuple[TubularComponent, ...]


@dataclass(frozen=True)
class GeometrySection:
    kind: str  # typeHoleCasing: casing, liner, riser, open hole, ...
    top: float
    bottom: float
    inner_diameter: float
    outer_diameter: float | None = None

    @property
    def is_open(self) -> bool:
        return self.kind.lower().replace(" ", "") in ("openhole", "open")


@dataclass(frozen=True)
class WellboreGeometry:
    uid: str
    name: str
    source: str
    sections: tuple[GeometrySection, ...]


@dataclass(frozen=True)
class Rig:
    name: str
    source: str
    block_weight: float | None  # [N]


@dataclass(frozen=True)
class FluidReport:
    source: str
    when: str
    density: float | None  # [kg/m3]


@dataclass(frozen=True)
class WellObjects:
    """What the given object files held (several tubulars, one of each of the others)."""

    well: str = ""
    trajectory: Trajectory | None = None
    tubulars: tuple[Tubular, ...] = ()
    geometry: WellboreGeometry | None = None
    rig: Rig | None = None
    fluid: FluidReport | None = None


# -- parsing -----------------------------------------------------------------------------------

def _children(element: ET.Element, name: str) -> list[ET.Element]:
    return [child for child in element if local_name(child.tag) == name]


def _child(element: ET.Element, name: str) -> ET.Element | None:
    found = _children(element, name)
    return found[0] if found else None


def _measure(element: ET.Element, name: str, target: str, source: str,
             where: str, signed: bool = False) -> tuple[float, str] | None:
    """(value in ``target``, the uom read) of child ``name``; None when absent, below 0 (a
    null such as -9999) unless ``signed``, or a -999.25 / -9999 style null when signed."""
    child = _child(element, name)
    if child is None or not (child.text or "").strip():
        return None
    uom = child.get("uom", "")
    try:
        value = float(child.text or "")
    except ValueError:
        raise IngestError(f"{source}: {where}/{name}: '{child.text}' is not a number") from None
    if not math.isfinite(value) or (value < 0 and not signed) or value <= -999.0:
        return None
    unit = pint_unit(uom) or target
    try:
        scale, offset = conversion(unit, target)
    except ValueError as exc:
        raise IngestError(f"{source}: {where}/{name}: uom '{uom}': {exc}") from None
    return value * scale + offset, uom


def _required(element: ET.Element, name: str, target: str, source: str, where: str) -> float:
    found = _measure(element, name, target, source, where)
    if found is None:
        raise IngestError(f"{source}: {where} has no {name} (or a negative one)")
    return found[0]


def parse_trajectory(element: ET.Element, source: str) -> Trajectory:
    """A ``trajectory`` element: its stations in md order, angles in degrees."""
    uid = element.get("uid", "")
    stations: list[Station] = []
    uoms: dict[str, str] = {}
    for index, station in enumerate(_children(element, "trajectoryStation")):
        where = f"trajectory '{uid}' station {index}"
        values = []
        for name, target in (("md", "m"), ("incl", "degree"), ("azi", "degree")):
            # azimuths may be written from -180 to 180 deg: wrapped to 0-360 below
            found = _measure(station, name, target, source, where, signed=name == "azi")
            if found is None:
                break
            values.append(found[0] % 360.0 if name == "azi" else found[0])
            uoms.setdefault(name, found[1])
        if len(values) == 3:
            stations.append(Station(*values))
    stations.sort(key=lambda item: item.md)
    unique = [station for i, station in enumerate(stations)
              if i == 0 or station.md > stations[i - 1].md + 1e-9]
    if len(unique) < 2:
        raise IngestError(f"{source}: trajectory '{uid}' has fewer than two stations with md, "
                          "incl and azi")
    units = ", ".join(f"{name} {uom or '?'}" for name, uom in uoms.items())
    return Trajectory(uid, child_text(element, "name") or "", source, tuple(unique), units)


def parse_tubular(element: ET.Element, source: str) -> Tubular:
    """A ``tubular`` element: its components from the bit up."""
    uid = element.get("uid", "")
    components = []
    for index, item in enumerate(_children(element, "tubularComponent")):
        where = f"tubular '{uid}' component {item.get('uid', index)}"
        weight = _weight(item, source, where)
        connection = _child(item, "connection")
        connection_od = (_measure(connection, "od", "m", source, where)
                         if connection is not None else None)
        yield_found = _measure(item, "tensYield", "Pa", source, where)
        sequence_text = child_text(item, "sequence")
        components.append(TubularComponent(
            uid=item.get("uid", ""), kind=child_text(item, "typeTubularComp") or "component",
            sequence=int(sequence_text) if sequence_text and sequence_text.isdigit() else index,
            length=_required(item, "len", "m", source, where),
            od=_required(item, "od", "m", source, where),
            id=_required(item, "id", "m", source, where), weight=weight,
            connection_od=connection_od[0] if connection_od and connection_od[0] > 0 else None,
            yield_strength=yield_found[0] if yield_found and yield_found[0] > 0 else None))
    if not components:
        raise IngestError(f"{source}: tubular '{uid}' has no tubularComponent")
    components.sort(key=lambda component: component.sequence)
    common = _child(element, "commonData")
    created = (child_text(common, "dTimCreation") or "") if common is not None else ""
    return Tubular(uid, child_text(element, "name") or "", source,
                   child_text(element, "typeTubularAssy") or "", created, tuple(components))


def _weight(item: ET.Element, source: str, where: str) -> float | None:
    """``wtPerLen`` as a mass per length [kg/m] (a force per length is divided by g)."""
    child = _child(item, "wtPerLen")
    if child is None:
        return None
    uom = child.get("uom", "kg/m")
    unit = {"lbm/ft": "lb/ft", "lbf/ft": "lbf/ft"}.get(uom, pint_unit(uom) or "kg/m")
    try:
        value = float(child.text or "")
    except ValueError:
        raise IngestError(f"{source}: {where}/wtPerLen: '{child.text}' is not a number") from None
    if not value > 0:
        return None
    try:
        return value * conversion(unit, "kg/m")[0]
    except ValueError:
        try:
            return value * conversion(unit, "N/m")[0] / 9.80665
        except ValueError as exc:
            raise IngestError(f"{source}: {where}/wtPerLen: uom '{uom}': {exc}") from None


def parse_wb_geometry(element: ET.Element, source: str) -> WellboreGeometry:
    """A ``wbGeometry`` element: its sections by top depth."""
    uid = element.get("uid", "")
    sections = []
    for index, item in enumerate(_children(element, "wbGeometrySection")):
        where = f"wbGeometry '{uid}' section {item.get('uid', index)}"
        outer = _measure(item, "odSection", "m", source, where)
        sections.append(GeometrySection(
            kind=child_text(item, "typeHoleCasing") or "unknown",
            top=_required(item, "mdTop", "m", source, where),
            bottom=_required(item, "mdBottom", "m", source, where),
            inner_diameter=_required(item, "idSection", "m", source, where),
            outer_diameter=outer[0] if outer else None))
    if not sections:
        raise IngestError(f"{source}: wbGeometry '{uid}' has no wbGeometrySection")
    sections.sort(key=lambda section: (section.top, section.bottom))
    return WellboreGeometry(uid, child_text(element, "name") or "", source, tuple(sections))


def parse_rig(element: ET.Element, source: str) -> Rig:
    found = _measure(element, "wtBlock", "N", source, "rig")
    return Rig(child_text(element, "name") or "", source,
               found[0] if found and found[0] > 0 else None)


def parse_fluids_report(element: ET.Element, source: str) -> FluidReport:
    density = None
    for fluid in _children(element, "fluid"):
        found = _measure(fluid, "density", "kg/m**3", source, "fluidsReport/fluid")
        if found and found[0] > 0:
            density = found[0]
            break
    return FluidReport(source, child_text(element, "dTim") or "", density)


def read_objects(files: Iterable[tuple[IO[bytes], str]]) -> WellObjects:
    """Parse trajectory, tubular, wbGeometry, rig and fluidsReport files (small files: read
    whole). The last trajectory, wbGeometry, rig and fluids report given win.

    Raises
    ------
    IngestError
        Not XML, not one of these objects, or an element without a needed value.
    """
    objects = WellObjects()
    tubulars: list[Tubular] = []
    for stream, source in files:
        try:
            root = ET.parse(stream).getroot()
        except ET.ParseError as exc:
            raise IngestError(f"{source}: not well-formed XML ({exc})") from None
        kind = OBJECT_KINDS.get(local_name(root.tag))
        if kind is None or kind == "log":
            raise IngestError(f"{source}: not a WITSML trajectory, tubular, wbGeometry, rig or "
                              f"fluidsReport file (root element <{local_name(root.tag)}>)")
        for element in _children(root, kind):
            well = child_text(element, "nameWell") or objects.well
            if kind == "trajectory":
                objects = _replace(objects, well=well,
                                   trajectory=parse_trajectory(element, source))
            elif kind == "tubular":
                tubulars.append(parse_tubular(element, source))
                objects = _replace(objects, well=well)
            elif kind == "wbGeometry":
                objects = _replace(objects, well=well,
                                   geometry=parse_wb_geometry(element, source))
            elif kind == "rig":
                objects = _replace(objects, well=well, rig=parse_rig(element, source))
            else:
                objects = _replace(objects, well=well,
                                   fluid=parse_fluids_report(element, source))
    return _replace(objects, tubulars=tuple(tubulars))


def _replace(objects: WellObjects, **changes: object) -> WellObjects:
    from dataclasses import replace

    return replace(objects, **changes)  # type: ignore[arg-type]


# -- the draft ---------------------------------------------------------------------------------

@dataclass(frozen=True)
class WellDraft:
    """The drafted TOML text and what the user must fill in or check (one line each)."""

    text: str
    missing: tuple[str, ...]
    notes: tuple[str, ...] = field(default=())


def nominal_weight(component: TubularComponent) -> tuple[float, str] | None:
    """(API nominal weight [lb/ft], designation) matching a component's kind and size."""
    kind = component.kind.lower()
    family = ("drill pipe" if "drill pipe" in kind or kind in ("dp", "heavy weight drill pipe")
              else "casing" if kind in ("tubing", "casing", "liner") else None)
    if family is None:
        return None
    od_in, id_in = component.od / _INCH, component.id / _INCH
    best = None
    for entry_kind, od, inner, weight in NOMINAL_WEIGHTS:
        kinds = ("casing", "tubing") if family == "casing" else ("drill pipe",)
        if entry_kind in kinds and abs(od - od_in) <= 0.01 and abs(inner - id_in) <= 0.03:
            gap = abs(inner - id_in)
            if best is None or gap < best[0]:
                best = (gap, weight, f"{od:g} in x {inner:g} in ID, API "
                        f"{'5DP' if entry_kind == 'drill pipe' else '5CT'}")
    return (best[1], best[2]) if best else None


def _hole_intervals(sections: tuple[GeometrySection, ...]) -> list[tuple[float, float,
                                                                         GeometrySection]]:
    """Non-overlapping intervals, each with the narrowest section covering it (a liner inside
    a casing, a casing inside the open hole drilled before it)."""
    edges = sorted({edge for section in sections for edge in (section.top, section.bottom)})
    intervals: list[tuple[float, float, GeometrySection]] = []
    for top, bottom in itertools.pairwise(edges):
        covering = [section for section in sections
                    if section.top <= top + 1e-9 and section.bottom >= bottom - 1e-9]
        if not covering:
            continue
        narrowest = min(covering, key=lambda section: section.inner_diameter)
        if intervals and intervals[-1][2] is narrowest and abs(intervals[-1][1] - top) < 1e-9:
            intervals[-1] = (intervals[-1][0], bottom, narrowest)
        else:
            intervals.append((top, bottom, narrowest))
    return intervals


def _q(value: float, unit: str, digits: int = 6) -> str:
    return f'"{value:.{digits}g} {unit}"'


def _plain_tube_mass(component: TubularComponent) -> float:
    """Mass per length of the component as a plain steel tube [kg/m]: eq 41 of the model
    (:func:`tdmon.model.string.weight_per_length`) divided by g."""
    return float(weight_per_length(component.od, component.id)) / GRAVITY


def _name_for(section: GeometrySection) -> str:
    size = section.outer_diameter or section.inner_diameter
    label = "open hole" if section.is_open else section.kind
    return f"{size / _INCH:.4g} in {label}"


def draft_well(objects: WellObjects, *, tubular: Tubular | None = None,  # noqa: C901  (complex today; simplify when next touched)
               block_weight: str | None = None, fluid_density: str | None = None,
               licence_note: str | None = None) -> WellDraft:
    """The well file text from parsed objects.

    Parameters
    ----------
    objects : what the files held; needs a trajectory, a wbGeometry and a tubular
    tubular : which string (default: the only one; several need a choice)
    block_weight, fluid_density : quantities with units (e.g. ``"655 kN"``, ``"1.08 sg"``) that
        WITSML lacks, written as given; otherwise the rig's ``wtBlock`` and the fluids report's
        density when present, else left for the user
    licence_note : a comment line for the top (e.g. the data's licence)

    Raises
    ------
    IngestError
        A needed object is missing, or several tubulars and none chosen.
    """
    missing_objects = [name for name, value in (("trajectory", objects.trajectory),
                                                ("wbGeometry", objects.geometry))
                       if value is None]
    if tubular is None:
        if not objects.tubulars:
            missing_objects.append("tubular")
        elif len(objects.tubulars) > 1:
            raise IngestError(
                "several tubulars given (" + ", ".join(
                    f"uid {item.uid} '{item.name}' in {item.source}, created {item.created}"
                    for item in objects.tubulars)
                + "): which string was in the hole cannot be read from them; choose one with "
                  "--tubular UID")
        else:
            tubular = objects.tubulars[0]
    if missing_objects:
        raise IngestError(f"--well-out: no {', '.join(missing_objects)} object among the files "
                          "(a well file needs a trajectory, a wbGeometry and a tubular)")
    assert objects.trajectory is not None and objects.geometry is not None
    assert tubular is not None
    trajectory, geometry = objects.trajectory, objects.geometry
    missing: list[str] = []
    notes: list[str] = []

    # -- well
    if block_weight is not None:
        block_line = f'block_weight = "{block_weight}"'
    elif objects.rig is not None and objects.rig.block_weight is not None:
        block_line = f"block_weight = {_q(objects.rig.block_weight / 1000, 'kN')}  # rig wtBlock"
    else:
        block_line = '# block_weight = "40 t"  # FILL IN: travelling block + top drive'
        missing.append("well.block_weight: not in the WITSML (rig wtBlock absent or -9999); "
                       "without it the hook load lacks the block and top drive (read it as the "
                       "hook load with the string in slips)")

    # -- hole sections
    intervals = _hole_intervals(geometry.sections)
    last_md = trajectory.stations[-1].md
    hole_lines: list[str] = []
    string_od = max(component.connection_od or component.od for component in tubular.components)
    for top, bottom, section in intervals:
        if top >= last_md - 1e-6:
            notes.append(f"hole section {section.kind} {top:g}-{bottom:g} m left out: below the "
                         f"last survey station ({last_md:g} m)")
            continue
        bottom = min(bottom, last_md)
        kind = "open" if section.is_open else "cased"
        default_mu = 0.30 if kind == "open" else 0.25
        hole_lines += [
            "[[hole]]", f'name = "{_name_for(section)}"', f'kind = "{kind}"',
            f"top = {_q(top, 'm')}", f"bottom = {_q(bottom, 'm')}",
            f"diameter = {_q(section.inner_diameter, 'm')}",
            f"# friction = {default_mu:.2f}  # FILL IN: calibrate (tdmon replay) or from offset "
            "wells", ""]
        if section.inner_diameter <= string_od + 1e-6:
            missing.append(f"hole {top:g}-{bottom:g} m ({section.kind}): diameter "
                           f"{section.inner_diameter:.4g} m is not larger than the string's OD "
                           f"({string_od:.4g} m): check the wbGeometry (bit size?)")
    missing.append("hole[*].friction: WITSML has no friction factors (commented defaults 0.25 "
                   "cased, 0.30 open hole)")

    # -- string, from the bit up
    string_lines: list[str] = []
    for index, component in enumerate(tubular.components):
        lines = ["[[string]]", f'name = "{component.kind} (uid {component.uid})"',
                 f"length = {_q(component.length, 'm')}", f"od = {_q(component.od, 'm')}",
                 f"id = {_q(component.id, 'm')}"]
        if component.weight is not None:
            lines.append(f"weight = {_q(component.weight, 'kg/m')}  # wtPerLen")
        else:
            nominal = nominal_weight(component)
            if nominal is not None:
                lines.append(f'weight = "{nominal[0]:g} lb/ft"  # API nominal, {nominal[1]}')
                missing.append(f"string[{index}].weight: no wtPerLen; drafted as the API nominal "
                               f"weight of {nominal[1]} ({nominal[0]:g} lb/ft): check against "
                               "the pipe tally")
            else:
                plain = _plain_tube_mass(component)
                lines.append(f"# weight = {_q(plain, 'kg/m', 4)}  # FILL IN: in air, with tool "
                             "joints (suggested: the plain tube, eq 41)")
                missing.append(f"string[{index}].weight: no wtPerLen and no API size match; "
                               "the model uses the plain tube (eq 41), light by the tool joints")
        if component.connection_od is not None:
            lines.append(f"tool_joint_od = {_q(component.connection_od, 'm')}  # connection od")
        else:
            lines.append(f"# tool_joint_od = {_q(component.od / _INCH, 'in', 4)}  # FILL IN: the "
                         "connection's OD, the torque radius (suggested: the body OD, as "
                         "without it)")
            missing.append(f"string[{index}].tool_joint_od: no connection od (torque acts at "
                           "the body OD without it)")
        if component.yield_strength is not None:
            lines.append(f"yield_strength = {_q(component.yield_strength / 1e6, 'MPa')}")
        else:
            lines.append('# yield_strength = "552 MPa"  # FILL IN: grade (L-80: 552 MPa)')
        lines.append("# makeup_torque: the connection's make-up torque, from its data sheet "
                     "(optional)")
        string_lines += [*lines, ""]
    string_length = sum(component.length for component in tubular.components)

    # -- fluid
    if fluid_density is not None:
        fluid_lines = ["[fluid]", f'density = "{fluid_density}"']
    elif objects.fluid is not None and objects.fluid.density is not None:
        fluid_lines = ["[fluid]", f"density = {_q(objects.fluid.density, 'kg/m**3')}  "
                                  f"# fluidsReport {objects.fluid.when}"]
    else:
        fluid_lines = ["[fluid]", '# density = "1.2 sg"  # FILL IN: the mud in the hole (the '
                                  "file does not load without it)"]
        missing.insert(0, "fluid.density: not in the WITSML (no fluidsReport); the file does "
                          "not load until it is given (buoyancy changes the hook load by "
                          "10-20 %)")

    # -- survey
    station_lines = [f"  [{station.md:.6f}, {station.incl_deg:.6f}, {station.azi_deg:.6f}],"
                     for station in trajectory.stations]

    header = ["# Well file drafted by `tdmon import witsml` from WITSML 1.4.1.1 objects of "
              f"'{objects.well or '?'}':",
              f"#   trajectory '{trajectory.name}' (uid {trajectory.uid}, {trajectory.source}): "
              f"{len(trajectory.stations)} stations ({trajectory.units})",
              f"#   tubular '{tubular.name}' (uid {tubular.uid}, {tubular.source}): "
              f"{len(tubular.components)} component(s), {string_length:g} m, from the bit up",
              f"#   wbGeometry '{geometry.name}' (uid {geometry.uid}, {geometry.source}): "
              f"{len(geometry.sections)} section(s)"]
    if objects.rig is not None:
        header.append(f"#   rig '{objects.rig.name}' ({objects.rig.source})")
    if licence_note:
        header.append(f"# {licence_note}")
    header.append("#")
    header.append("# NOT READ FROM THE WITSML: fill in or check before trusting the loads")
    header += [f"#   - {item}" for item in missing]
    header += [f"#   note: {item}" for item in notes]
    body = [
        "", "[well]", f'name = "{objects.well or trajectory.name}"',
        'element_length = "10 m"', block_line, "",
        "[survey]",
        'angle_unit = "deg"',
        f"# md [m], inclination and azimuth [deg] from trajectory uid {trajectory.uid}",
        "stations = [", *station_lines, "]", "",
        *hole_lines, *string_lines, *fluid_lines, "",
        "[limits]", "safety_factor = 1.25  # a default: the operator's design factor", "",
    ]
    return WellDraft("\n".join(header + body), tuple(missing), tuple(notes))


def choose_tubular(objects: WellObjects, key: str) -> Tubular:
    """The tubular whose uid or name is ``key``.

    Raises
    ------
    IngestError
        None matches (the message lists them).
    """
    for tubular in objects.tubulars:
        if key in (tubular.uid, tubular.name):
            return tubular
    listed = ", ".join(f"{item.uid} '{item.name}'" for item in objects.tubulars) or "none given"
    raise IngestError(f"--tubular {key}: no tubular with that uid or name ({listed})")

