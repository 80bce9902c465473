"""What the drilling fluid adds to one march of the torque-and-drag model, per hole-grid element.

`FluidTerms` is the model's input (`tdmon.model.torque_drag.WellModel` takes it in every call):
an axial force per metre on every element (the viscous drag of the mud on the moving string and
the drag of the annular flow, `tdmon.model.fluid_force`), the force the fluid puts on the string
at the bit (the jets' reaction while circulating), and the density of the fluid outside and
inside the string at every element (a pill, pipe run unfilled: `tdmon.model.fluid_state`).
`pack_fluid` turns the terms of a march's operations into the one array the element loop reads
(`tdmon.model._kernels`). docs/hydraulics.md has the equations.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np
from numpy.typing import ArrayLike, NDArray

from tdmon.errors import ModelError

__all__ = ["NO_FLUID", "FluidTerms", "pack_fluid"]

NO_FLUID: NDArray[np.float64] = np.empty((0, 0))
"""The kernels' fluid argument of a march without fluid terms (never written; not flagged
read-only, which numba would compile as another argument type)."""


def _per_element(values: ArrayLike | None, what: str) -> NDArray[np.float64] | None:
    if values is None:
        return None
    array = np.array(values, dtype=np.float64, order="C")  # a copy, then read only: a
    if array.ndim != 1 or not np.all(np.isfinite(array)):  # WellModel keeps it packed
        raise ModelError(f"{what} must be a 1-D array of finite numbers, one per hole-grid "
                         f"element, got shape {array.shape}")
    array.setflags(write=False)
    return array


@dataclass(frozen=True)
class FluidTerms:
    """The fluid's part in one operation's march, per element of the well's hole grid.

    Attributes
    ----------
    axial : axial fluid force per metre of string on each element [N/m], tension positive at
        the top (the string's weight has this sign; a drag resisting a pull is positive), or
        None (0); elements the string does not reach are not read
    bit_force : force of the fluid on the string at the bit [N], tension positive (the jets'
        reaction while circulating is negative: it pushes the string up)
    outside_density, inside_density : fluid density outside and inside the string on each
        element [kg/m^3], or None (the well's fluid): they buoy each piece's weight by eq 36

    The arrays are copies of those given, read only.
    """

    axial: NDArray[np.float64] | None = None
    bit_force: float = 0.0
    outside_density: NDArray[np.float64] | None = None
    inside_density: NDArray[np.float64] | None = None

    def __post_init__(self) -> None:
        object.__setattr__(self, "axial", _per_element(self.axial, "axial fluid force"))
        object.__setattr__(self, "outside_density",
                           _per_element(self.outside_density, "outside density"))
        object.__setattr__(self, "inside_density",
                           _per_element(self.inside_density, "inside density"))
        object.__setattr__(self, "bit_force", float(self.bit_force))

    @property
    def loops_read(self) -> bool:
        """Whether the element loop has anything to read (an axial force or a density)."""
        return (self.axial is not None or self.outside_density is not None
                or self.inside_density is not None)


def _same(first: NDArray[np.float64] | None, other: NDArray[np.float64] | None) -> bool:
    if first is None or other is None:
        return first is other
    return first is other or bool(np.array_equal(first, other))


def pack_fluid(terms: Sequence[FluidTerms | None], n_elements: int, outside_density: float,
               inside_density: float) -> NDArray[np.float64]:
    """The element loop's ``fluid`` array of a march of ``len(terms)`` operations.

    Parameters
    ----------
    terms : per operation its terms, or None (none for that operation)
    n_elements : elements of the hole grid
    outside_density, inside_density : the well's fluid [kg/m^3], from which the loop's density
        shifts are counted (the buoyed weights it holds are for these)

    Returns
    -------
    `NO_FLUID` when no operation has anything for the loop, else an array
    (n_op + 2, n_elements): each operation's axial force per metre, then the outside and inside
    density shifts.

    Raises
    ------
    ModelError
        An array of another length than the grid's, or operations of one march with different
        densities (the loop buoys once for all of them).
    """
    present = [t for t in terms if t is not None and t.loops_read]
    if not present:
        return NO_FLUID
    first = present[0]
    if (first.outside_density is not None or first.inside_density is not None) and not (
            np.isfinite(outside_density) and np.isfinite(inside_density)):
        raise ModelError("per-element fluid densities need the well's fluid density ([fluid] "
                         "density): its weights are buoyed from it")
    for other in present[1:]:
        if not (_same(first.outside_density, other.outside_density)
                and _same(first.inside_density, other.inside_density)):
            raise ModelError("the operations of one march must share their fluid densities")
    packed = np.zeros((len(terms) + 2, n_elements))
    for row, term in enumerate(terms):
        if term is not None and term.axial is not None:
            packed[row] = _checked(term.axial, n_elements, "axial fluid force")
    for row, density, base in ((len(terms), first.outside_density, outside_density),
                               (len(terms) + 1, first.inside_density, inside_density)):
        if density is not None:
            packed[row] = _checked(density, n_elements, "fluid density") - base
    return packed


def _checked(values: NDArray[np.float64], n_elements: int, what: str) -> NDArray[np.float64]:
    if values.size != n_elements:
        raise ModelError(f"{what} must have one value per hole-grid element ({n_elements}), got "
                         f"{values.size}")
    return values
