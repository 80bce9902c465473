"""Torque and drag: hook load and surface torque of a drill string for each rig operation.

Two methods, named for what they are:

``"soft-string"``
    The 3D soft-string model of Johancsik et al. (1984): the string is a cable lying on the low
    or high side of the hole; each element's contact force comes from the bend of the axial
    force and the element's buoyed weight, with the consistent sign convention (in a build,
    tension and weight push the pipe to opposite sides). Evaluated piece by piece on the
    `tdmon.model.well.hole_grid` elements.
``"aadnoy"``
    The thesis's method as published: eq 42/45 on straight intervals, the build-section formulas
    of Tables 20-22 (Aadnoy, Mechanics of Drilling) on planar build arcs, and the Aadnoy,
    Fazaelizadeh and Hareland (2010) interval formulas on any other arc; each formula is applied
    to a whole survey interval (split only at section and component boundaries and at the bit),
    as the thesis does. It reproduces the thesis's Example 7.1 numbers, including the
    overestimated pick-up and torque that come from adding tension and weight normal forces in
    the build.

Forces are effective (buoyed) axial forces [N], tension positive; torques [N m]. The hook load is
the force at the top of the hole plus the travelling-block weight. See docs/torque-drag.md.
"""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from functools import cached_property, lru_cache
from typing import Any, Literal

import numpy as np
from numpy.typing import ArrayLike, NDArray

from tdmon.errors import ModelError
from tdmon.model import kernels
from tdmon.model.fluid_terms import NO_FLUID, FluidTerms, pack_fluid
from tdmon.model.kernels import Engine
from tdmon.model.survey import tangent_vectors, tvd_and_inclination
from tdmon.model.well import HoleGrid, Well, hole_grid, section_friction
from tdmon.vocabulary import Operation

__all__ = ["METHODS", "FluidTerms", "Loads", "Method", "Operation", "WellModel", "torque_drag"]

Method = Literal["soft-string", "aadnoy"]
METHODS: tuple[str, ...] = ("soft-string", "aadnoy")

# Bit depths this close [m] outside the string or the hole are taken as on the limit.
_DEPTH_TOLERANCE = 1e-6


@dataclass(frozen=True)
class Loads:
    """Loads of one bit depth for every operation.

    Attributes
    ----------
    bit_depth : [m]
    method : ``"soft-string"`` or ``"aadnoy"``
    hookload : per operation name, force at the top plus block weight [N]
    surface_torque : per operation name [N m] (0 for operations without rotation)
    md : MD of the string nodes, surface to bit [m]
    axial_force : per operation, effective axial force at the nodes, tension positive [N]
    torque : per operation, torque at the nodes [N m]
    tvd : TVD of the nodes [m]
    component : index (bit-up) of the string component just below each node
    inclination : inclination of the nodes [rad], from the same survey interpolation as
        ``tvd`` (None when the maker did not give it; the limits then interpolate it again)
    """

    bit_depth: float
    method: str
    hookload: dict[str, float]
    surface_torque: dict[str, float]
    md: NDArray[np.float64]
    axial_force: dict[str, NDArray[np.float64]]
    torque: dict[str, NDArray[np.float64]]
    tvd: NDArray[np.float64]
    component: NDArray[np.int64]
    inclination: NDArray[np.float64] | None = None


@dataclass(frozen=True)
class _OperationTerms:
    bit_force: float
    bit_torque: float
    axial_factor: float  # multiplies mu in the axial balance: +1 pulling, -1 lowering
    torque_factor: float  # multiplies mu in the torque balance: 1 rotating, 0 not


def operation_terms(
    operation: Operation | str, *, wob: float = 0.0, bit_torque: float = 0.0,
    psi: float | None = None,
) -> tuple[float, float, float, float]:
    """Bit force [N], bit torque [N m] and the axial/tangential friction multipliers [-].

    With ``psi`` (angle of the pipe's surface velocity from the tangential direction [rad],
    ``psi = atan(V_axial / V_tangential)``) a moving string that also rotates gets
    ``mu sin(psi)`` axially and ``mu cos(psi)`` tangentially; without it pick-up and slack-off
    are pure axial motion. On bottom the bit pushes back with -WOB (compression) and adds its
    torque.
    """
    op = Operation(operation)
    if op is Operation.STATIC:
        return 0.0, 0.0, 0.0, 0.0
    if op is Operation.ROTATING:
        return 0.0, 0.0, 0.0, 1.0
    if op is Operation.ON_BOTTOM:
        return -float(wob), float(bit_torque), 0.0, 1.0
    sign = 1.0 if op is Operation.PICK_UP else -1.0
    if psi is None:
        return 0.0, 0.0, sign, 0.0
    return 0.0, 0.0, sign * math.sin(psi), math.cos(psi)


# the terms of the calls the calibration repeats, computed once (an enum lookup and a few
# branches, about 1 us: a third of `evaluate`'s fixed cost)
@lru_cache(maxsize=256)
def _cached_terms(operation: Operation | str, wob: float, bit_torque: float,
                  psi: float | None) -> tuple[float, float, float, float]:
    # positional: lru_cache builds its key faster without keywords
    return operation_terms(operation, wob=wob, bit_torque=bit_torque, psi=psi)

_KERNEL_METHODS = {"soft-string": kernels.SOFT_STRING, "aadnoy": kernels.AADNOY}


def _check_method(method: str) -> int:
    kernel_method = _KERNEL_METHODS.get(method)
    if kernel_method is not None:
        return kernel_method
    raise ModelError(f"unknown torque-and-drag method {method!r}: use one of {', '.join(METHODS)}")


def _curve_kinds(well: Well, grid: HoleGrid) -> NDArray[np.int64]:
    """Curve kind of the survey interval each element lies on (see `kernels`)."""
    survey = well.survey
    interval = np.clip(
        np.searchsorted(survey.md, grid.element_mid_md, side="right") - 1, 0, survey.md.size - 2
    )
    inc_top = survey.inclination[interval]
    inc_bottom = survey.inclination[interval + 1]
    d_azi = np.angle(np.exp(1j * (survey.azimuth[interval + 1] - survey.azimuth[interval])))
    planar = (np.abs(d_azi) < 1e-6) | (inc_top < 1e-7) | (inc_bottom < 1e-7)
    curved = survey.dogleg[interval + 1] >= 1e-7
    kinds = np.full(interval.size, kernels.GENERAL_CURVE, dtype=np.int64)
    kinds[~curved] = kernels.STRAIGHT
    kinds[curved & planar & (inc_bottom > inc_top)] = kernels.PLANAR_BUILD
    return kinds


def _run_breaks(well: Well, grid: HoleGrid) -> NDArray[np.bool_]:
    """Nodes where an Aadnoy run must end: survey stations and section boundaries."""
    marks = np.concatenate([well.survey.md, [s.top for s in well.sections]])
    nearest = np.clip(np.searchsorted(grid.md, marks), 1, grid.md.size - 1)
    nearest = np.where(
        np.abs(grid.md[nearest - 1] - marks) < np.abs(grid.md[nearest] - marks), nearest - 1,
        nearest,
    )
    breaks = np.zeros(grid.md.size, dtype=bool)
    breaks[nearest[np.abs(grid.md[nearest] - marks) < 1e-6]] = True
    breaks[0] = True
    return np.asarray(breaks)


def _check_friction_values(loops: Any, values: NDArray[np.float64], what: str) -> None:
    """Raise unless every friction factor of the C-contiguous ``values`` is finite and >= 0
    (``loops``: the model's kernels module)."""
    if not loops.all_finite_non_negative(values.reshape(-1)):
        raise ModelError(f"{what} must be finite and >= 0")


class WellModel:
    """A well prepared for repeated torque-and-drag evaluation.

    The hole grid, the element geometry and the string's per-component arrays are computed
    once; `evaluate` then costs one compiled march from the bit to surface. This is the form the
    live back-calculation and the broomstick use.

    Parameters
    ----------
    well : the well
    engine : how the element loops run (`tdmon.model.kernels`): ``"numba"`` compiled, or
        ``"python"`` interpreted (the same numbers; quicker for a few calls in a fresh
        process, far slower per call); default ``TDMON_KERNELS``, else ``"numba"``
    """

    def __init__(self, well: Well, *, engine: Engine | str | None = None) -> None:
        self.well = well
        self.grid = hole_grid(well)
        grid = self.grid
        self.node_md = np.ascontiguousarray(grid.md)
        string = well.string
        self.component_top = np.ascontiguousarray(string.component_tops())
        self.component_weight = np.array(
            [c.buoyed_weight_in(well.fluid.density, well.fluid.inside_density)
             for c in string.components], dtype=np.float64)
        self.component_radius = np.array([c.torque_radius for c in string.components],
                                         dtype=np.float64)
        sensitivity = np.array([c.density_sensitivity() for c in string.components],
                               dtype=np.float64).reshape(-1, 2)
        fluid = well.fluid
        self._fluid_densities = (fluid.density, fluid.density if fluid.inside_density is None
                                 else fluid.inside_density)
        self._section_mu: NDArray[np.float64] | None = None
        # the kernels (`kernels.load`), typed loosely: mypy cannot see into numba's dispatchers
        self.kernels = kernels.load(engine)
        self._loops: Any = self.kernels.module
        self._march_one: Any = self._loops.march_one
        # what every kernel call reads, packed once (see `kernels.KernelWell`)
        self.kernel_well = kernels.kernel_well(
            self.kernels,
            node_md=self.node_md,
            tangents=tangent_vectors(grid.inclination, grid.azimuth),
            dogleg=grid.dogleg,
            curve_kind=_curve_kinds(well, grid),
            run_break=_run_breaks(well, grid),
            component_top=self.component_top,
            component_weight=self.component_weight,
            component_radius=self.component_radius,
            component_outside_sensitivity=sensitivity[:, 0],
            component_inside_sensitivity=sensitivity[:, 1],
        )
        self._well_real, self._well_index = self.kernel_well
        self._max_nodes = grid.n_elements + len(string.components) + 2
        # `check_bit_depth`'s limits as floats, and uniform friction arrays by value: the
        # calibration calls `evaluate` thousands of times with the same few
        # the usual bit depths: above the shallowest and down to the deepest allowed
        self._depth_above = float(self.node_md[0]) + _DEPTH_TOLERANCE
        self._depth_down_to = min(float(string.length), float(self.node_md[-1]))
        self._uniform: dict[float, NDArray[np.float64]] = {}
        self._last_fluid: tuple[tuple[int, ...], tuple[FluidTerms | None, ...],
                                NDArray[np.float64]] | None = None

    @property
    def n_elements(self) -> int:
        """Number of hole-grid elements (the length of a per-element friction array)."""
        return self.grid.n_elements

    def friction(self, mu: float | ArrayLike | None) -> NDArray[np.float64]:
        """Per-element friction factors from None (sections), a number or an array [-]."""
        if mu is None:
            if self._section_mu is None:
                self._section_mu = np.ascontiguousarray(section_friction(self.well, self.grid))
            return self._section_mu
        if isinstance(mu, float | int) and not isinstance(mu, bool):
            return self._uniform_friction(float(mu)).copy()
        values = np.asarray(mu, dtype=np.float64)
        if values.ndim == 0:
            return self._uniform_friction(float(values)).copy()
        if values.shape != (self.n_elements,):
            raise ModelError(
                f"per-element friction must have one value per hole-grid element "
                f"({self.n_elements}), got shape {values.shape}"
            )
        values = np.ascontiguousarray(values)
        _check_friction_values(self._loops, values, "per-element friction factors")
        return values

    def _uniform_friction(self, value: float) -> NDArray[np.float64]:
        """One friction factor on every element, kept by value; read only by the kernels."""
        uniform = self._uniform.get(value)
        if uniform is None:
            if not (math.isfinite(value) and value >= 0.0):
                raise ModelError(f"friction factor must be a finite number >= 0, got {value}")
            if len(self._uniform) >= 64:
                self._uniform.clear()
            uniform = self._uniform[value] = np.full(self.n_elements, value)
        return uniform

    def kernel_fluid(self, terms: Sequence[FluidTerms | None]) -> NDArray[np.float64]:
        """The element loop's fluid argument of a march of these operations' terms.

        The last one packed is kept with the terms it came from (their arrays are read only):
        a sample's terms are evaluated many times over (the back-calculation's iterations),
        and packing n_elements values costs more than a shallow march."""
        ids = tuple(map(id, terms))
        last = self._last_fluid
        if last is not None and last[0] == ids:
            return last[2]
        kept = tuple(terms)  # held with their ids: no other object takes one while kept
        packed = pack_fluid(kept, self.n_elements, *self._fluid_densities)
        self._last_fluid = (ids, kept, packed)
        return packed

    def _kernel_friction(self, mu: float | ArrayLike | None) -> NDArray[np.float64]:
        """`friction` for the kernels: a uniform one is shared, not copied (they only read)."""
        if isinstance(mu, float | int) and not isinstance(mu, bool):
            return self._uniform_friction(float(mu))
        return self.friction(mu)

    @cached_property
    def _node_tvd_inclination(self) -> tuple[NDArray[np.float64], NDArray[np.float64]] | None:
        """The survey's TVD [m] and inclination [rad] at the grid's nodes, interpolated once
        (None for a grid reaching past the survey: every node is then interpolated)."""
        try:
            return tvd_and_inclination(self.well.survey, self.node_md)
        except ModelError:
            return None

    def _tvd_and_inclination(self, md: NDArray[np.float64]
                             ) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
        """`tvd_and_inclination` of the survey at the nodes ``md`` of a march [m], to the
        last bit: the hole-grid nodes among them (all but the string's component tops and
        the bit) taken from the grid's, interpolated once, the others interpolated here.

        Each depth's numbers are worked out from it alone, element by element, so a depth
        gives the same bits among any others (`tests/model/test_torque_drag.py` holds the two
        to each other). With `limits._component_table`, the calibration's limit check went
        241 -> 198 us a window (bench_calibration, the 3.3 h session); the few off-grid nodes
        still pay the interpolation's fixed cost.
        """
        survey = self.well.survey
        nodes = self.node_md
        if not (md.size > 1 and nodes[0] <= md[0] and md[-1] <= nodes[-1]
                and np.isfinite(md).all() and (md[1:] - md[:-1] > 0).all()):
            # what the interpolation would refuse, or cannot be taken apart: refused as one
            return tvd_and_inclination(survey, md)
        at_nodes = self._node_tvd_inclination
        if at_nodes is None:
            return tvd_and_inclination(survey, md)
        node_tvd, node_inclination = at_nodes
        index = np.searchsorted(nodes, md)  # md <= nodes[-1]: a valid index
        tvd, inclination = node_tvd[index], node_inclination[index]
        off_grid = nodes[index] != md
        if off_grid.any():
            tvd[off_grid], inclination[off_grid] = tvd_and_inclination(survey, md[off_grid])
        return tvd, inclination

    def check_bit_depth(self, bit_depth: float) -> float:
        """Validate a bit depth against the string and the hole; returns it as float [m]."""
        depth = float(bit_depth)
        if self._depth_above < depth <= self._depth_down_to:
            return depth  # the usual case, checked with one comparison
        string_length = self.well.string.length
        if not math.isfinite(depth):
            raise ModelError(f"bit depth must be finite, got {bit_depth}")
        if depth > string_length + _DEPTH_TOLERANCE:
            raise ModelError(
                f"bit depth {depth:.2f} m is deeper than the drill string is long "
                f"({string_length:.2f} m)"
            )
        top, bottom = self.node_md[0], self.node_md[-1]
        if depth > bottom + _DEPTH_TOLERANCE:
            raise ModelError(
                f"bit depth {depth:.2f} m is below the hole (bottom of the hole sections and "
                f"survey: {bottom:.2f} m)"
            )
        if depth <= top + _DEPTH_TOLERANCE:
            raise ModelError(f"bit depth {depth:.2f} m must lie below the top of the hole "
                             f"({top:.2f} m)")
        return min(depth, float(bottom))

    def evaluate(
        self,
        operation: Operation | str,
        bit_depth: float,
        mu: float | ArrayLike | None = None,
        *,
        method: Method | str = "soft-string",
        wob: float = 0.0,
        bit_torque: float = 0.0,
        psi: float | None = None,
        fluid: FluidTerms | None = None,
    ) -> tuple[float, float]:
        """Hook load [N] and surface torque [N m] of one operation at one bit depth.

        Parameters
        ----------
        operation : `Operation` or its name
        bit_depth : [m]
        mu : friction factor: None (the sections'), a number, or one per hole-grid element [-]
        method : ``"soft-string"`` or ``"aadnoy"``
        wob : weight on bit for ``on_bottom`` [N]
        bit_torque : bit torque for ``on_bottom`` [N m]
        psi : combined motion angle for pick-up/slack-off while rotating [rad]
        fluid : the fluid's terms of this operation (`FluidTerms`: viscous drag, the jets'
            force at the bit, densities per element); None: none
        """
        # the calibration's call: every step inlined where it costs more as a call
        kernel_method = _KERNEL_METHODS.get(method)
        if kernel_method is None:
            kernel_method = _check_method(method)
        depth = float(bit_depth)
        if not self._depth_above < depth <= self._depth_down_to:
            depth = self.check_bit_depth(depth)
        friction = self._uniform.get(mu) if type(mu) is float else None
        if friction is None:
            friction = self._kernel_friction(mu)
        bit_force, bit_torque_term, axial_factor, torque_factor = _cached_terms(
            operation, wob, bit_torque, psi)
        terms = NO_FLUID
        if fluid is not None:
            terms = self.kernel_fluid((fluid,))
            bit_force += fluid.bit_force
        # positional: the fast path of numba's dispatch
        force, torque = self._march_one(self._well_real, self._well_index, kernel_method,
                                        friction, depth, bit_force, bit_torque_term,
                                        axial_factor, torque_factor, terms)
        return force + self.well.block_weight, torque

    def evaluate_cases(
        self,
        operation: Operation | str,
        bit_depth: float,
        mu_cases: ArrayLike,
        *,
        method: Method | str = "soft-string",
        wob: float = 0.0,
        bit_torque: float = 0.0,
        psi: float | None = None,
        fluid: FluidTerms | None = None,
    ) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
        """`evaluate` for several friction cases at once, in one march.

        Parameters
        ----------
        operation, bit_depth, method, wob, bit_torque, psi, fluid : as in `evaluate`
        mu_cases : (n_cases, n_elements) per-element friction factors, one row per case [-]

        Returns
        -------
        hook loads [N] and surface torques [N m], (n_cases,) each; every case's numbers are
        `evaluate`'s bit for bit, at a fraction of the cost of one call per case.
        """
        kernel_method = _check_method(method)
        depth = self.check_bit_depth(bit_depth)
        cases = np.ascontiguousarray(mu_cases, dtype=np.float64)
        if cases.ndim != 2 or cases.shape[1] != self.n_elements or cases.shape[0] == 0:
            raise ModelError(
                f"friction cases must be an array (n_cases, {self.n_elements}) with one value "
                f"per hole-grid element, got shape {cases.shape}"
            )
        _check_friction_values(self._loops, cases, "friction factors")
        terms = np.array(_cached_terms(operation, wob, bit_torque, psi))
        if fluid is not None:
            terms[0] += fluid.bit_force
        forces, torques = self._loops.march_cases(
            *self.kernel_well, kernel_method, cases, depth, terms[0:1], terms[1:2], terms[2:3],
            terms[3:4], NO_FLUID if fluid is None else self.kernel_fluid((fluid,)))
        return forces[:, 0] + self.well.block_weight, torques[:, 0]

    def evaluate_gradient(
        self,
        operation: Operation | str,
        bit_depth: float,
        mu: float | ArrayLike | None = None,
        *,
        quantity_index: int = 0,
        method: Method | str = "soft-string",
        wob: float = 0.0,
        bit_torque: float = 0.0,
        psi: float | None = None,
        fluid: FluidTerms | None = None,
    ) -> tuple[float, NDArray[np.float64]]:
        """Hook load [N] or surface torque [N m] and its gradient with respect to the friction
        factor of every hole-grid element, from one march up and one sweep back down.

        Parameters
        ----------
        operation, bit_depth, mu, method, wob, bit_torque, psi, fluid : as in `evaluate`
        quantity_index : 0 for the hook load, 1 for the surface torque (`evaluate`'s order)

        Returns
        -------
        value : as `evaluate` returns it [N or N m]
        gradient : d value / d mu per element, shape (n_elements,) [N or N m]; 0 for elements
            the string does not reach

        Notes
        -----
        Reverse-mode (adjoint) differentiation of the march. With ``lam_F = dq/dF`` and
        ``lam_T = dq/dT`` (q the chosen quantity; ``lam_T`` is constant since torque only adds),
        seeded at the top with (1, 0) for the hook load or (0, 1) for the torque, each soft-string
        piece of `torque_drag` (Notes) is stepped back from the top to the bit::

            N_b = N(F),  F_p = F + w dTVD + mu_a N_b,  N_t = N(F_p),  N = (N_b + N_t) / 2
            lam_N   = lam_F mu_a + lam_T mu_t r
            lam_F_p = lam_N N'(F_p) / 2
            dq/dmu += (lam_F a + lam_T t r) N + lam_F_p a N_b
            lam_F   = lam_F + lam_F_p + (lam_N / 2 + lam_F_p mu_a) N'(F)

        with ``mu_a = a mu``, ``mu_t = t mu`` (a, t the operation's axial and tangential
        friction multipliers) and ``N'(F) = (F kk + w ke) / N``, F being the force at the
        piece's bottom kept from the forward march. For ``"aadnoy"`` the same is done run by
        run with the derivatives of its closed forms; a run's friction is the length-weighted
        mean of its elements', so ``dq/dmu_element = dq/dmu_run * piece length / run length``.
        Where the march has a kink (N clipped at 0, |F| in the 2010 torque formula, the
        pick-up/slack-off build formulas meeting at mu = 0) the derivative is that of the
        branch the forward march takes. The value equals `evaluate`'s.
        """
        if quantity_index not in (0, 1):
            raise ModelError(f"quantity index must be 0 (hook load) or 1 (torque), "
                             f"got {quantity_index}")
        kernel_method = _check_method(method)
        depth = self.check_bit_depth(bit_depth)
        friction = self._kernel_friction(mu)
        bit_force, bit_torque_term, axial_factor, torque_factor = operation_terms(
            operation, wob=wob, bit_torque=bit_torque, psi=psi)
        terms = NO_FLUID
        if fluid is not None:
            terms = self.kernel_fluid((fluid,))
            bit_force += fluid.bit_force
        force, torque, gradient = self._loops.march_gradient(
            *self.kernel_well, kernel_method, friction, depth, bit_force, bit_torque_term,
            axial_factor, torque_factor, terms, 1.0 - quantity_index, float(quantity_index))
        if quantity_index == 0:
            return float(force) + self.well.block_weight, gradient
        return float(torque), gradient

    def profiles(
        self,
        operations: Sequence[Operation | str],
        bit_depth: float,
        mu: float | ArrayLike | None = None,
        *,
        method: Method | str = "soft-string",
        wob: float = 0.0,
        bit_torque: float = 0.0,
        psi: float | None = None,
        fluid: FluidTerms | Mapping[str, FluidTerms] | None = None,
    ) -> tuple[NDArray[np.float64], NDArray[np.float64], NDArray[np.float64], NDArray[np.int64]]:
        """Loads along the string for several operations in one march.

        ``fluid``: one `FluidTerms` for every operation, or per operation name (an operation
        left out has none; all share one set of densities).

        Returns
        -------
        md : node MD, surface to bit [m]
        axial_force : (n_operations, n_nodes) [N]
        torque : (n_operations, n_nodes) [N m]
        component : index (bit-up) of the string component just below each node
        """
        kernel_method = _check_method(method)
        depth = self.check_bit_depth(bit_depth)
        friction = self._kernel_friction(mu)
        terms = np.array([operation_terms(op, wob=wob, bit_torque=bit_torque, psi=psi)
                          for op in operations]).reshape(-1, 4)
        per_operation = _fluid_per_operation(fluid, operations)
        for row, term in enumerate(per_operation):
            if term is not None:
                terms[row, 0] += term.bit_force
        size = self._max_nodes
        md = np.empty(size)
        force = np.empty((terms.shape[0], size))
        torque = np.empty((terms.shape[0], size))
        component = np.empty(size, dtype=np.int64)
        tangent = np.empty((size, 3))
        count = self._loops.march_profile(
            *self.kernel_well, kernel_method, friction, depth,
            np.ascontiguousarray(terms[:, 0]), np.ascontiguousarray(terms[:, 1]),
            np.ascontiguousarray(terms[:, 2]), np.ascontiguousarray(terms[:, 3]),
            self.kernel_fluid(per_operation), md, force, torque, component, tangent)
        return (md[:count][::-1].copy(), force[:, :count][:, ::-1].copy(),
                torque[:, :count][:, ::-1].copy(), component[:count][::-1].copy())

    def loads(
        self,
        bit_depth: float,
        mu: float | ArrayLike | None = None,
        *,
        method: Method | str = "soft-string",
        wob: float = 0.0,
        bit_torque: float = 0.0,
        psi: float | None = None,
        operations: Sequence[Operation | str] | None = None,
        fluid: FluidTerms | Mapping[str, FluidTerms] | None = None,
    ) -> Loads:
        """`Loads` (of every operation, or of ``operations``, with profiles) at one bit depth;
        see `torque_drag` (``fluid`` as in `profiles`).

        Each operation's loads are those of a march of all, so the calibration's limit check
        asks for the two it reads (the march 46 -> 38 us).
        """
        chosen = list(Operation) if operations is None else list(
            dict.fromkeys(Operation(op) for op in operations))
        md, force, torque, component = self.profiles(
            chosen, bit_depth, mu, method=method, wob=wob, bit_torque=bit_torque, psi=psi,
            fluid=fluid)
        names = [op.value for op in chosen]
        # one interpolation for both: the limit check needs the nodes' inclination too
        tvd, inclination = self._tvd_and_inclination(md)
        return Loads(
            bit_depth=float(bit_depth), method=str(method),
            hookload={name: float(force[i, 0]) + self.well.block_weight
                      for i, name in enumerate(names)},
            surface_torque={name: float(torque[i, 0]) for i, name in enumerate(names)},
            md=md,
            axial_force={name: force[i] for i, name in enumerate(names)},
            torque={name: torque[i] for i, name in enumerate(names)},
            tvd=tvd,
            component=component,
            inclination=inclination,
        )


def _fluid_per_operation(fluid: FluidTerms | Mapping[str, FluidTerms] | None,
                         operations: Sequence[Operation | str]) -> list[FluidTerms | None]:
    """One `FluidTerms` (or None) per operation of a march."""
    if fluid is None or isinstance(fluid, FluidTerms):
        return [fluid] * len(operations)
    by_name = {Operation(name).value: terms for name, terms in fluid.items()}
    unknown = set(by_name) - {Operation(op).value for op in operations}
    if unknown:
        raise ModelError(f"fluid terms for operations not marched: {', '.join(sorted(unknown))}")
    return [by_name.get(Operation(op).value) for op in operations]


def torque_drag(
    well: Well,
    bit_depth: float,
    mu: float | ArrayLike | None = None,
    *,
    method: Method | str = "soft-string",
    wob: float = 0.0,
    bit_torque: float = 0.0,
    psi: float | None = None,
    engine: Engine | str | None = None,
) -> Loads:
    """Hook load, surface torque and load profiles of every operation at one bit depth.

    Parameters
    ----------
    well : the well
    bit_depth : MD of the bit [m]; at most the string's length and the hole's bottom
    mu : friction factor [-]: None uses each hole section's ``friction``; a number applies
        everywhere; an array gives one value per element of ``hole_grid(well)``
    method : ``"soft-string"`` (consistent 3D soft string) or ``"aadnoy"`` (the thesis's
        formulas as published)
    wob : weight on bit for the ``on_bottom`` operation [N]
    bit_torque : torque at the bit for ``on_bottom`` [N m]
    psi : angle of combined motion for pick-up and slack-off while rotating [rad]; friction
        splits into ``mu sin(psi)`` axially and ``mu cos(psi)`` tangentially
    engine : how the element loops run, as for `WellModel` (the same numbers either way)

    Returns
    -------
    Loads

    Raises
    ------
    ModelError
        Bit depth deeper than the string or the hole, unknown method, bad friction array, a
        section without friction when ``mu`` is None.

    Notes
    -----
    Soft string, per piece of length dL with buoyed weight W = w dL, unit tangents t_b (bottom)
    and t_t (top) and mean direction t_m::

        N = | F (t_b - t_t) + W (e_z - (e_z . t_m) t_m) |
        F_top = F_bottom + w dTVD +/- mu N      (+ pick-up, - slack-off, 0 rotating/static)
        T_top = T_bottom + mu N r

    which is Johancsik's ``N = sqrt((F dphi sin a)^2 + (F da + W sin a)^2)`` with
    ``da = a_top - a_bottom`` in vector form. For the straight element this is eq 42 (pick-up
    and slack-off) and eq 45 (torque) of the thesis. The Aadnoy formulas are listed in
    docs/torque-drag.md.

    References
    ----------
    .. [1] Johancsik, C. A., Friesen, D. B. and Dawson, R. (1984). Torque and drag in
       directional wells - prediction and measurement. JPT 36(6), 987-992.
    .. [2] Aadnoy, B. S. (2006). Mechanics of Drilling. Shaker Verlag. Example 7.1.
    .. [3] Aadnoy, B. S., Fazaelizadeh, M. and Hareland, G. (2010). A 3D analytical model for
       wellbore friction. J. Can. Pet. Technol. 49(10), 25-36.
    """
    return WellModel(well, engine=engine).loads(bit_depth, mu, method=method, wob=wob,
                                                bit_torque=bit_torque, psi=psi)
