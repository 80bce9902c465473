"""Compiled element loops of the torque-and-drag model (numba).

The physics is documented in `tdmon.model.torque_drag` and docs/torque-drag.md; this module only
holds the loops, written for speed: scalars instead of small arrays, no allocation in the loops.

Geometry arrives as the hole grid (node MD, node unit tangents, element dogleg, a curve kind per
element and a run-break flag per node) and the string as cumulative component tops measured from
the bit, with a buoyed weight and a friction radius per component. The march goes from the bit up
to the top of the hole in *pieces*: a piece is the part of a grid element between the bit, the
element's nodes and the string's component boundaries, so each piece has one weight, one radius,
one friction factor and lies on one circular arc. `march_gradient` is the same march for one
operation followed by its adjoint: the value and its gradient with respect to every element's
friction factor.

The per-well arrays travel packed in two flat buffers (built once per well by `pack_well`); the
entry points take them and the per-call values. The same functions run under numba's JIT and,
compiled ahead of time by `tdmon.model.aot`, without numba: `tdmon.model.kernels` picks one.
"""

from __future__ import annotations

import math
from collections import namedtuple

import numpy as np
from numba import njit

# the method and the curve kinds are named where the model (without numba) reads them
from tdmon.model.kernels import PLANAR_BUILD, SOFT_STRING

_STRAIGHT_DOGLEG = 1e-7
_MD_TOLERANCE = 1e-9


@njit(cache=True)
def _tangent_at(node_md, tangents, dogleg, j, md):
    """Unit tangent at ``md`` inside element ``j``, on the element's circular arc."""
    length = node_md[j + 1] - node_md[j]
    f = (md - node_md[j]) / length
    beta = dogleg[j]
    if beta < _STRAIGHT_DOGLEG:
        w1 = 1.0 - f
        w2 = f
    else:
        s = math.sin(beta)
        w1 = math.sin((1.0 - f) * beta) / s
        w2 = math.sin(f * beta) / s
    x = w1 * tangents[j, 0] + w2 * tangents[j + 1, 0]
    y = w1 * tangents[j, 1] + w2 * tangents[j + 1, 1]
    z = w1 * tangents[j, 2] + w2 * tangents[j + 1, 2]
    norm = math.sqrt(x * x + y * y + z * z)
    return x / norm, y / norm, z / norm


@njit(cache=True)
def _angle_between(ax, ay, az, bx, by, bz):
    """Angle between two unit vectors, accurate for small angles."""
    dx = bx - ax
    dy = by - ay
    dz = bz - az
    half_chord = 0.5 * math.sqrt(dx * dx + dy * dy + dz * dz)
    if half_chord > 1.0:
        half_chord = 1.0
    return 2.0 * math.asin(half_chord)


@njit(cache=True)
def _inclination(x, y, z):
    return math.atan2(math.sqrt(x * x + y * y), z)


@njit(cache=True)
def piece_geometry(tt, tb, length):
    """Geometry of one piece for the soft-string balance.

    Returns ``(kk, ke, ee, dtvd)``: with ``k = t_b - t_t`` scaled to the arc's dogleg and
    ``e = (e_z - (e_z . t_m) t_m) length`` (t_m the mean direction), the contact force of the
    piece is ``N = |F k + w e| = sqrt(F^2 kk + 2 F w ke + w^2 ee)``; ``dtvd`` is the exact TVD
    change along the arc.
    """
    dx = tb[0] - tt[0]
    dy = tb[1] - tt[1]
    dz = tb[2] - tt[2]
    chord = math.sqrt(dx * dx + dy * dy + dz * dz)
    if chord > 1e-12:
        half = min(0.5 * chord, 1.0)
        beta = 2.0 * math.asin(half)
        arc_over_chord = beta / chord  # the bend of the force is the dogleg, not the chord
    else:
        beta = 0.0
        arc_over_chord = 1.0
    kx = dx * arc_over_chord
    ky = dy * arc_over_chord
    kz = dz * arc_over_chord
    mx = tt[0] + tb[0]
    my = tt[1] + tb[1]
    mz = tt[2] + tb[2]
    mnorm = math.sqrt(mx * mx + my * my + mz * mz)
    mx /= mnorm
    my /= mnorm
    mz /= mnorm
    ex = -mz * mx * length
    ey = -mz * my * length
    ez = (1.0 - mz * mz) * length
    ratio = 1.0 + beta * beta / 12.0 if beta < 1e-4 else 2.0 / beta * math.tan(0.5 * beta)
    dtvd = 0.5 * length * (tt[2] + tb[2]) * ratio
    return (kx * kx + ky * ky + kz * kz, kx * ex + ky * ey + kz * ez,
            ex * ex + ey * ey + ez * ez, dtvd)


@njit(cache=True)
def element_geometry(node_md, tangents):
    """`piece_geometry` of every whole grid element: arrays kk, ke, ee, dtvd."""
    n = node_md.size - 1
    kk = np.empty(n)
    ke = np.empty(n)
    ee = np.empty(n)
    dtvd = np.empty(n)
    for j in range(n):
        tt = (tangents[j, 0], tangents[j, 1], tangents[j, 2])
        tb = (tangents[j + 1, 0], tangents[j + 1, 1], tangents[j + 1, 2])
        kk[j], ke[j], ee[j], dtvd[j] = piece_geometry(tt, tb, node_md[j + 1] - node_md[j])
    return kk, ke, ee, dtvd


# --- the per-well arguments, packed ---
#
# Two flat buffers rather than twelve arrays or a structref: every array argument is unboxed on
# each call (about 0.05 us each, in numba's dispatcher and in the ahead-of-time module alike),
# and a structref cannot cross into the ahead-of-time module (its Python handle is numba's).
# The entry points unpack the buffers into `_WellArrays`, views the loops read by name.

_WellArrays = namedtuple("_WellArrays", [
    "node_md", "tangents", "dogleg", "curve_kind", "run_break", "element_kk", "element_ke",
    "element_ee", "element_dtvd", "component_top", "component_weight", "component_radius"])

# the index buffer starts with the sizes: nodes, elements, components
_HEADER = 3


@njit(cache=True)
def pack_well(node_md, tangents, dogleg, curve_kind, run_break, component_top,
              component_weight, component_radius):
    """Pack a well's arrays into the two buffers every entry point takes, and add the whole
    elements' `piece_geometry`.

    Hole grid: ``node_md`` (n_nodes,) [m], ``tangents`` (n_nodes, 3) unit tangents [-],
    ``dogleg`` (n_elements,) [rad], ``curve_kind`` (n_elements,) (`STRAIGHT`, `PLANAR_BUILD`,
    `GENERAL_CURVE`), ``run_break`` (n_nodes,) where an Aadnoy run ends. String, bit first:
    ``component_top`` (n_components,) cumulative top from the bit [m], ``component_weight``
    buoyed weight per length [N/m], ``component_radius`` friction radius of the torque [m].
    Every array C-contiguous, float64 but ``curve_kind`` (int64) and ``run_break`` (bool).

    Returns ``(real, index)``: float64 node MD, tangents, dogleg, the elements' kk, ke, ee,
    dtvd and the three component arrays, in this order; int64 sizes (`_HEADER`), curve kinds
    and run breaks (0 or 1).
    """
    n_nodes = node_md.size
    n_elements = dogleg.size
    n_components = component_top.size
    real = np.empty(4 * n_nodes + 5 * n_elements + 3 * n_components)
    index = np.empty(_HEADER + n_elements + n_nodes, dtype=np.int64)
    index[0] = n_nodes
    index[1] = n_elements
    index[2] = n_components
    kk, ke, ee, dtvd = element_geometry(node_md, tangents)
    at = 0
    for part in (node_md, tangents.ravel(), dogleg, kk, ke, ee, dtvd, component_top,
                 component_weight, component_radius):
        real[at:at + part.size] = part
        at += part.size
    index[_HEADER:_HEADER + n_elements] = curve_kind
    for i in range(n_nodes):
        index[_HEADER + n_elements + i] = 1 if run_break[i] else 0
    return real, index


@njit(cache=True)
def _unpack(real, index):
    """The `_WellArrays` views of `pack_well`'s buffers."""
    n_nodes = index[0]
    n_el = index[1]
    n_comp = index[2]
    t = n_nodes  # where each part starts
    d = t + 3 * n_nodes
    g = d + n_el
    c = g + 4 * n_el
    k = _HEADER + n_el
    return _WellArrays(
        real[:n_nodes], real[t:d].reshape((n_nodes, 3)), real[d:g], index[_HEADER:k],
        index[k:k + n_nodes], real[g:g + n_el], real[g + n_el:g + 2 * n_el],
        real[g + 2 * n_el:g + 3 * n_el], real[g + 3 * n_el:c], real[c:c + n_comp],
        real[c + n_comp:c + 2 * n_comp], real[c + 2 * n_comp:c + 3 * n_comp])


@njit(cache=True)
def all_finite_non_negative(values):
    """Whether every value of a 1-D array is finite and >= 0 (friction checks: one compiled
    pass instead of two numpy reductions, each of which costs about 1 us on a short array)."""
    for v in values:  # noqa: SIM110 (a loop: numba does not compile all() of a generator)
        if not (v >= 0.0 and v < math.inf):  # NaN fails both
            return False
    return True


@njit(cache=True)
def _normal_force(force, weight, kk, ke, ee):
    squared = force * force * kk + 2.0 * force * weight * ke + weight * weight * ee
    return math.sqrt(squared) if squared > 0.0 else 0.0


@njit(cache=True)
def _soft_string_piece(force, kk, ke, ee, dtvd, weight, axial_mu):
    """One piece of the 3D soft-string march: returns (force at the top, normal force).

    The contact force is ``N = |F (t_b - t_t) + W (e_z - (e_z . t_m) t_m)|``, the vector form of
    Johancsik's ``sqrt((F dphi sin a)^2 + (F da + W sin a)^2)`` with ``da = a_top - a_bottom``;
    the vector form needs no sign convention and no azimuth wrapping. The force entering N is
    averaged over the piece (Heun's predictor-corrector) rather than taken at the bottom.
    """
    axial_weight = weight * dtvd
    n_bottom = _normal_force(force, weight, kk, ke, ee)
    predicted = force + axial_weight + axial_mu * n_bottom
    n_top = _normal_force(predicted, weight, kk, ke, ee)
    normal = 0.5 * (n_bottom + n_top)
    return force + axial_weight + axial_mu * normal, normal


@njit(cache=True)
def _aadnoy_run(force, torque, top_inc, bottom_inc, length, theta, kind, mu, axial_factor,
                torque_factor, weight, radius):
    """Closed-form step over one run (arc or straight) as Aadnoy publishes it.

    Straight: eq 42 and eq 45 of the thesis. Planar build (inclination rising with depth):
    Tables 20-22 of the thesis, generalised from (0, alpha) to (a_top, a_bottom). Any other arc:
    Aadnoy, Fazaelizadeh and Hareland (2010), tension dominated.
    """
    mu_axial = axial_factor * mu
    mu_torque = torque_factor * mu
    if theta < _STRAIGHT_DOGLEG:
        a = 0.5 * (top_inc + bottom_inc)
        new_force = force + weight * length * (math.cos(a) + mu_axial * math.sin(a))
        new_torque = torque + mu_torque * weight * length * radius * math.sin(a)
        return new_force, new_torque
    if kind == PLANAR_BUILD and bottom_inc > top_inc:
        sweep = bottom_inc - top_inc
        wr = weight * length / sweep
        lift = wr * (math.sin(bottom_inc) - math.sin(top_inc))
        if mu_axial > 0.0:
            new_force = (force + lift) * math.exp(mu_axial * sweep)
        elif mu_axial < 0.0:
            m = -mu_axial
            c = wr / (1.0 + m * m)
            k_bottom = c * ((1.0 - m * m) * math.sin(bottom_inc) - 2.0 * m * math.cos(bottom_inc))
            k_top = c * ((1.0 - m * m) * math.sin(top_inc) - 2.0 * m * math.cos(top_inc))
            new_force = (force + k_bottom) * math.exp(-m * sweep) - k_top
        else:
            new_force = force + lift
        new_torque = torque + mu_torque * radius * (
            (force + lift) * sweep + 2.0 * wr * (math.cos(top_inc) - math.cos(bottom_inc))
        )
        return new_force, new_torque
    if abs(bottom_inc - top_inc) > 1e-9:
        lift = weight * length * (math.sin(bottom_inc) - math.sin(top_inc)) / (bottom_inc - top_inc)
    else:
        lift = weight * length * math.cos(bottom_inc)
    new_force = force * math.exp(mu_axial * theta) + lift
    new_torque = torque + mu_torque * radius * abs(force) * theta
    return new_force, new_torque


@njit(cache=True)
def _soft_string_step(force, torque, kk, ke, ee, dtvd, weight, radius, mu, axial_factors,
                      torque_factors):
    """Advance every operation's force and torque over one piece (in place)."""
    for o in range(force.size):
        force[o], normal = _soft_string_piece(force[o], kk, ke, ee, dtvd, weight,
                                              axial_factors[o] * mu)
        torque[o] += torque_factors[o] * mu * normal * radius


@njit(cache=True)
def _aadnoy_run_nodes(run_force, run_torque, run_md, run_tan, run_mu, kind, weight, radius,
                      axial_factors, torque_factors, first, k, out_md, out_force, out_torque,
                      out_tan):
    """Write a closed run's profile: the run's closed form from its bottom state to every node
    recorded inside it (the last one is the run's top)."""
    bottom_inc = _inclination(run_tan[0], run_tan[1], run_tan[2])
    for i in range(first, k):
        theta = _angle_between(out_tan[i, 0], out_tan[i, 1], out_tan[i, 2],
                               run_tan[0], run_tan[1], run_tan[2])
        top_inc = _inclination(out_tan[i, 0], out_tan[i, 1], out_tan[i, 2])
        for o in range(run_force.size):
            out_force[o, i], out_torque[o, i] = _aadnoy_run(
                run_force[o], run_torque[o], top_inc, bottom_inc, run_md - out_md[i], theta,
                kind, run_mu, axial_factors[o], torque_factors[o], weight, radius)


@njit(cache=True)
def _record(k, md, comp, tangent, force, torque, out_md, out_force, out_torque, out_comp,
            out_tan):
    out_md[k] = md
    out_comp[k] = comp
    out_tan[k, 0] = tangent[0]
    out_tan[k, 1] = tangent[1]
    out_tan[k, 2] = tangent[2]
    for o in range(force.size):
        out_force[o, k] = force[o]
        out_torque[o, k] = torque[o]


@njit(cache=True)
def _march(well, method, mu, bit_depth, bit_forces, bit_torques, axial_factors, torque_factors,
           out_md, out_force, out_torque, out_comp, out_tan):
    """March from the bit to the top of the hole for several operations at once.

    An operation is a (bit force, bit torque, axial friction factor, torque friction factor)
    quadruple; the pieces and their geometry are shared by all. Returns (n recorded, top
    forces, top torques). Given non-empty ``out_*`` arrays (see `march_profile`) the node MD,
    component index (of the piece below the node) and tangent, and per operation the axial
    force and torque, are written into them bit first; Aadnoy runs write their nodes when the
    run closes. Empty ones record nothing.
    """
    # a run-time test, not a flag argument: a literal flag would compile the march twice
    record = out_md.size > 0
    # the loop reads local arrays, as it did when they were arguments
    node_md = well.node_md
    tangents = well.tangents
    dogleg = well.dogleg
    el_kk = well.element_kk
    el_ke = well.element_ke
    el_ee = well.element_ee
    el_dtvd = well.element_dtvd
    curve_kind = well.curve_kind
    run_break = well.run_break
    comp_top = well.component_top
    comp_weight = well.component_weight
    comp_radius = well.component_radius
    n_comp = comp_top.size
    j = min(max(np.searchsorted(node_md, bit_depth) - 1, 0), node_md.size - 2)
    comp = 0
    lower = bit_depth
    tb = _tangent_at(node_md, tangents, dogleg, j, lower)
    force = bit_forces.copy()
    torque = bit_torques.copy()
    k = 0
    if record:
        _record(0, lower, 0, tb, force, torque, out_md, out_force, out_torque, out_comp, out_tan)
        k = 1
    # Aadnoy runs: the state at the run's bottom and its length-weighted friction
    run_force = force.copy()
    run_torque = torque.copy()
    run_md = lower
    run_tan = tb
    run_mu_length = 0.0
    run_first = k
    while True:
        element_top = node_md[j]
        component_top = bit_depth - comp_top[comp]
        while comp < n_comp - 1 and component_top >= lower - _MD_TOLERANCE:
            comp += 1
            component_top = bit_depth - comp_top[comp]
        at_component_top = comp < n_comp - 1 and component_top > element_top + _MD_TOLERANCE
        if at_component_top:
            upper = component_top
            tt = _tangent_at(node_md, tangents, dogleg, j, upper)
        else:
            upper = element_top
            tt = (tangents[j, 0], tangents[j, 1], tangents[j, 2])
        length = lower - upper
        if method == SOFT_STRING:
            if at_component_top or lower < node_md[j + 1]:
                kk, ke, ee, dtvd = piece_geometry(tt, tb, length)
            else:
                kk, ke, ee, dtvd = el_kk[j], el_ke[j], el_ee[j], el_dtvd[j]
            _soft_string_step(force, torque, kk, ke, ee, dtvd, comp_weight[comp],
                              comp_radius[comp], mu[j], axial_factors, torque_factors)
            if record:
                _record(k, upper, comp, tt, force, torque, out_md, out_force, out_torque,
                        out_comp, out_tan)
                k += 1
        else:
            run_mu_length += mu[j] * length
            if record:
                _record(k, upper, comp, tt, force, torque, out_md, out_force, out_torque,
                        out_comp, out_tan)
                k += 1
            component_ends = comp < n_comp - 1 and component_top >= upper - _MD_TOLERANCE
            at_node = not at_component_top
            if component_ends or (at_node and (run_break[j] or j == 0)):
                run_mu = run_mu_length / (run_md - upper)
                weight = comp_weight[comp]
                radius = comp_radius[comp]
                if record:
                    _aadnoy_run_nodes(run_force, run_torque, run_md, run_tan, run_mu,
                                      curve_kind[j], weight, radius, axial_factors,
                                      torque_factors, run_first, k, out_md, out_force,
                                      out_torque, out_tan)
                    for o in range(force.size):
                        force[o] = out_force[o, k - 1]
                        torque[o] = out_torque[o, k - 1]
                else:
                    bottom_inc = _inclination(run_tan[0], run_tan[1], run_tan[2])
                    top_inc = _inclination(tt[0], tt[1], tt[2])
                    theta = _angle_between(tt[0], tt[1], tt[2], run_tan[0], run_tan[1],
                                           run_tan[2])
                    for o in range(force.size):
                        force[o], torque[o] = _aadnoy_run(
                            run_force[o], run_torque[o], top_inc, bottom_inc, run_md - upper,
                            theta, curve_kind[j], run_mu, axial_factors[o], torque_factors[o],
                            weight, radius)
                for o in range(force.size):  # an element loop: slice copies cost more here
                    run_force[o] = force[o]
                    run_torque[o] = torque[o]
                run_md = upper
                run_tan = tt
                run_mu_length = 0.0
                run_first = k
        lower = upper
        tb = tt
        if at_component_top:
            comp += 1
        elif j == 0:
            break
        else:
            j -= 1
    return k, force, torque


@njit(cache=True)
def march(well_real, well_index, method, mu, bit_depth, bit_forces, bit_torques, axial_factors,
          torque_factors):
    """Force and torque at the top of the hole for several operations, marched together.

    Parameters
    ----------
    well_real, well_index : the well, packed by `pack_well`
    method : `SOFT_STRING` or `AADNOY`
    mu : (n_elements,) friction factor per element [-]
    bit_depth : [m], inside the string and the hole
    bit_forces, bit_torques : (n_op,) force [N] and torque [N m] at the bit per operation
    axial_factors, torque_factors : (n_op,) multipliers of mu in the axial and the torque
        balance per operation [-]

    Returns
    -------
    (n_op,) forces [N] and (n_op,) torques [N m] at the top
    """
    no_float_2d = np.empty((0, 0))
    _, force, torque = _march(
        well=_unpack(well_real, well_index), method=method, mu=mu, bit_depth=bit_depth,
        bit_forces=bit_forces, bit_torques=bit_torques, axial_factors=axial_factors,
        torque_factors=torque_factors,
        out_md=np.empty(0), out_force=no_float_2d, out_torque=no_float_2d,
        out_comp=np.empty(0, dtype=np.int64), out_tan=np.empty((0, 3)))
    return force, torque


@njit(cache=True)
def _march_cases(well, method, mu_cases, bit_depth, bit_forces, bit_torques, axial_factors,
                 torque_factors, forces, torques):
    """`_march` without recording for several friction cases at once: writes the top force and
    torque of every (case, operation) into ``forces`` and ``torques`` (n_case, n_op).

    The pieces, their geometry and the Aadnoy runs depend on the bit depth only, so they are
    found once for all cases; each (case, operation) then takes exactly `_march`'s steps, in
    the same order, and gets its numbers bit for bit. The cases are independent chains of
    square roots and divisions, which the processor overlaps: that, and the shared geometry,
    is why several cases cost little more than one.
    """
    node_md = well.node_md
    tangents = well.tangents
    dogleg = well.dogleg
    el_kk = well.element_kk
    el_ke = well.element_ke
    el_ee = well.element_ee
    el_dtvd = well.element_dtvd
    curve_kind = well.curve_kind
    run_break = well.run_break
    comp_top = well.component_top
    comp_weight = well.component_weight
    comp_radius = well.component_radius
    n_comp = comp_top.size
    n_case = mu_cases.shape[0]
    n_op = bit_forces.size
    j = min(max(np.searchsorted(node_md, bit_depth) - 1, 0), node_md.size - 2)
    comp = 0
    lower = bit_depth
    tb = _tangent_at(node_md, tangents, dogleg, j, lower)
    for c in range(n_case):
        for o in range(n_op):
            forces[c, o] = bit_forces[o]
            torques[c, o] = bit_torques[o]
    # Aadnoy runs: the state at the run's bottom and each case's length-weighted friction
    run_force = forces.copy()
    run_torque = torques.copy()
    run_mu_length = np.zeros(n_case)
    run_md = lower
    run_tan = tb
    while True:
        element_top = node_md[j]
        component_top = bit_depth - comp_top[comp]
        while comp < n_comp - 1 and component_top >= lower - _MD_TOLERANCE:
            comp += 1
            component_top = bit_depth - comp_top[comp]
        at_component_top = comp < n_comp - 1 and component_top > element_top + _MD_TOLERANCE
        if at_component_top:
            upper = component_top
            tt = _tangent_at(node_md, tangents, dogleg, j, upper)
        else:
            upper = element_top
            tt = (tangents[j, 0], tangents[j, 1], tangents[j, 2])
        length = lower - upper
        weight = comp_weight[comp]
        radius = comp_radius[comp]
        if method == SOFT_STRING:
            if at_component_top or lower < node_md[j + 1]:
                kk, ke, ee, dtvd = piece_geometry(tt, tb, length)
            else:
                kk, ke, ee, dtvd = el_kk[j], el_ke[j], el_ee[j], el_dtvd[j]
            for c in range(n_case):
                mu = mu_cases[c, j]
                for o in range(n_op):
                    forces[c, o], normal = _soft_string_piece(
                        forces[c, o], kk, ke, ee, dtvd, weight, axial_factors[o] * mu)
                    torques[c, o] += torque_factors[o] * mu * normal * radius
        else:
            for c in range(n_case):
                run_mu_length[c] += mu_cases[c, j] * length
            component_ends = comp < n_comp - 1 and component_top >= upper - _MD_TOLERANCE
            at_node = not at_component_top
            if component_ends or (at_node and (run_break[j] or j == 0)):
                bottom_inc = _inclination(run_tan[0], run_tan[1], run_tan[2])
                top_inc = _inclination(tt[0], tt[1], tt[2])
                theta = _angle_between(tt[0], tt[1], tt[2], run_tan[0], run_tan[1], run_tan[2])
                # `_aadnoy_run`'s straight run takes the sine and cosine of the run's mean
                # inclination: geometry only, so computed once for all cases here, then the
                # same products in the same order (the same numbers)
                straight = theta < _STRAIGHT_DOGLEG
                mean_inc = 0.5 * (top_inc + bottom_inc)
                cos_a = math.cos(mean_inc) if straight else 0.0
                sin_a = math.sin(mean_inc) if straight else 0.0
                run_length = run_md - upper
                for c in range(n_case):
                    run_mu = run_mu_length[c] / run_length
                    for o in range(n_op):
                        if straight:
                            forces[c, o] = run_force[c, o] + weight * run_length * (
                                cos_a + axial_factors[o] * run_mu * sin_a)
                            torques[c, o] = run_torque[c, o] + (
                                torque_factors[o] * run_mu * weight * run_length * radius * sin_a)
                        else:
                            forces[c, o], torques[c, o] = _aadnoy_run(
                                run_force[c, o], run_torque[c, o], top_inc, bottom_inc,
                                run_length, theta, curve_kind[j], run_mu, axial_factors[o],
                                torque_factors[o], weight, radius)
                        run_force[c, o] = forces[c, o]
                        run_torque[c, o] = torques[c, o]
                    run_mu_length[c] = 0.0
                run_md = upper
                run_tan = tt
        lower = upper
        tb = tt
        if at_component_top:
            comp += 1
        elif j == 0:
            break
        else:
            j -= 1


@njit(cache=True)
def march_cases(well_real, well_index, method, mu_cases, bit_depth, bit_forces, bit_torques,
                axial_factors, torque_factors):
    """`march` for several friction cases in one march: arrays (n_case, n_op) of the top
    forces [N] and torques [N m]; ``mu_cases`` is (n_case, n_elements), C-contiguous [-]."""
    forces = np.empty((mu_cases.shape[0], bit_forces.size))
    torques = np.empty((mu_cases.shape[0], bit_forces.size))
    _march_cases(_unpack(well_real, well_index), method, mu_cases, bit_depth, bit_forces,
                 bit_torques, axial_factors, torque_factors, forces, torques)
    return forces, torques


@njit(cache=True)
def march_one(well_real, well_index, method, mu, bit_depth, bit_force, bit_torque, axial_factor,
              torque_factor):
    """`march` of one operation and one friction array, as two floats: (top force [N], top
    torque [N m]). The operation's terms are scalars (`march_gradient`'s), and nothing is
    returned as an array, which keeps the call's fixed cost low."""
    forces = np.empty((1, 1))
    torques = np.empty((1, 1))
    _march_cases(_unpack(well_real, well_index), method, mu.reshape((1, mu.size)), bit_depth,
                 np.full(1, bit_force), np.full(1, bit_torque), np.full(1, axial_factor),
                 np.full(1, torque_factor), forces, torques)
    return forces[0, 0], torques[0, 0]


@njit(cache=True)
def march_profile(well_real, well_index, method, mu, bit_depth, bit_forces, bit_torques,
                  axial_factors, torque_factors, out_md, out_force, out_torque, out_comp,
                  out_tan):
    """`march` that also writes the loads at every node, bit first; returns the node count.

    The outputs have room for n_elements + n_components + 2 nodes: ``out_md`` [m],
    ``out_comp`` (index of the component below the node), ``out_tan`` (n, 3) unit tangent,
    and per operation ``out_force`` [N] and ``out_torque`` [N m], (n_op, n).
    """
    count, _, _ = _march(
        well=_unpack(well_real, well_index), method=method, mu=mu, bit_depth=bit_depth,
        bit_forces=bit_forces, bit_torques=bit_torques, axial_factors=axial_factors,
        torque_factors=torque_factors,
        out_md=out_md, out_force=out_force, out_torque=out_torque,
        out_comp=out_comp, out_tan=out_tan)
    return count


@njit(cache=True)
def sweep(well_real, well_index, method, mu_cases, bit_depths, bit_forces, bit_torques,
          axial_factors, torque_factors):
    """Surface force and torque for every (case, depth, operation): arrays (n_case, n_depth, n_op).

    ``mu_cases`` is (n_case, n_element); the other arguments are `march`'s.
    """
    n_case = mu_cases.shape[0]
    n_depth = bit_depths.size
    n_op = axial_factors.size
    forces = np.empty((n_case, n_depth, n_op))
    torques = np.empty((n_case, n_depth, n_op))
    top_forces = np.empty((n_case, n_op))
    top_torques = np.empty((n_case, n_op))
    well = _unpack(well_real, well_index)
    for d in range(n_depth):
        _march_cases(well, method, mu_cases, bit_depths[d], bit_forces, bit_torques,
                     axial_factors, torque_factors, top_forces, top_torques)
        forces[:, d, :] = top_forces
        torques[:, d, :] = top_torques
    return forces, torques


# --- adjoint: the march's value and its gradient with respect to every element's friction ---
#
# One operation, one output ``q = force_seed * F_top + torque_seed * T_top``. The forward pass
# is the march above (same operations in the same order, so the value is the march's to the
# bit); it keeps what the backward pass needs, the state at the bottom of each piece (soft
# string) or run (Aadnoy). The backward pass carries the adjoints ``lam_F = dq/dF`` and
# ``lam_T = dq/dT`` from the top down to the bit and adds each piece's or run's ``dq/dmu`` to its
# element. Where the march has a kink (the contact force at N = 0, |F| in Aadnoy's torque) the
# derivative is that of the branch the forward pass took.


@njit(cache=True)
def _normal_force_slope(force, weight, kk, ke, ee):
    """dN/dF of `_normal_force` (0 where the forward pass clips N to 0)."""
    squared = force * force * kk + 2.0 * force * weight * ke + weight * weight * ee
    if squared > 0.0:
        return (force * kk + weight * ke) / math.sqrt(squared)
    return 0.0


@njit(cache=True)
def _soft_string_piece_adjoint(force, kk, ke, ee, dtvd, weight, radius, mu, axial_factor,
                               torque_factor, lam_force, lam_torque):
    """Backward step over one `_soft_string_piece`: from the adjoints at the piece's top and the
    force at its bottom, returns (adjoint of the bottom force, dq/dmu of the piece)."""
    axial_mu = axial_factor * mu
    n_bottom = _normal_force(force, weight, kk, ke, ee)
    predicted = force + weight * dtvd + axial_mu * n_bottom
    n_top = _normal_force(predicted, weight, kk, ke, ee)
    normal = 0.5 * (n_bottom + n_top)
    lam_normal = lam_force * axial_mu + lam_torque * torque_factor * mu * radius
    lam_predicted = 0.5 * lam_normal * _normal_force_slope(predicted, weight, kk, ke, ee)
    lam_n_bottom = 0.5 * lam_normal + lam_predicted * axial_mu
    d_mu = ((lam_force * axial_factor + lam_torque * torque_factor * radius) * normal
            + lam_predicted * axial_factor * n_bottom)
    lam_bottom = (lam_force + lam_predicted
                  + lam_n_bottom * _normal_force_slope(force, weight, kk, ke, ee))
    return lam_bottom, d_mu


@njit(cache=True)
def _slack_off_k(a, weight_radius, m):
    """``K(a) = w R ((1 - m^2) sin a - 2 m cos a) / (1 + m^2)`` of the slack-off build formula
    and its derivative in m."""
    q = 1.0 + m * m
    g = (1.0 - m * m) * math.sin(a) - 2.0 * m * math.cos(a)
    dg = -2.0 * m * math.sin(a) - 2.0 * math.cos(a)
    return weight_radius * g / q, weight_radius * (dg * q - 2.0 * m * g) / (q * q)


@njit(cache=True)
def _build_slack_off_term(sweep_angle, weight_radius, m, top_inc, bottom_inc):
    """d/dm of ``K(a2) e^(-m s) - K(a1)`` in the slack-off build formula (the part of dF2/dm
    without F1); returns (that, e^(-m s))."""
    decay = math.exp(-m * sweep_angle)
    k_bottom, dk_bottom = _slack_off_k(bottom_inc, weight_radius, m)
    _, dk_top = _slack_off_k(top_inc, weight_radius, m)
    return dk_bottom * decay - sweep_angle * k_bottom * decay - dk_top, decay


@njit(cache=True)
def _aadnoy_run_adjoint(force, top_inc, bottom_inc, length, theta, kind, mu, axial_factor,
                        torque_factor, weight, radius, lam_force, lam_torque):
    """Backward step over one `_aadnoy_run` (same branches): from the adjoints at the run's
    top and the force at its bottom, returns (adjoint of the bottom force, dq/d(run friction)).
    The bottom torque's adjoint is the top's (torque adds)."""
    mu_axial = axial_factor * mu
    mu_torque = torque_factor * mu
    if theta < _STRAIGHT_DOGLEG:
        a = 0.5 * (top_inc + bottom_inc)
        d_mu = (lam_force * axial_factor * weight * length * math.sin(a)
                + lam_torque * torque_factor * weight * length * radius * math.sin(a))
        return lam_force, d_mu
    if kind == PLANAR_BUILD and bottom_inc > top_inc:
        sweep_angle = bottom_inc - top_inc
        wr = weight * length / sweep_angle
        lift = wr * (math.sin(bottom_inc) - math.sin(top_inc))
        # at mu = 0 the branch friction moves into: the formulas meet there
        if mu_axial > 0.0 or (mu_axial == 0.0 and axial_factor > 0.0):
            growth = math.exp(mu_axial * sweep_angle)
            d_force = (force + lift) * growth * sweep_angle * axial_factor
        elif mu_axial < 0.0 or (mu_axial == 0.0 and axial_factor < 0.0):
            d_force_dm, growth = _build_slack_off_term(sweep_angle, wr, -mu_axial, top_inc,
                                                       bottom_inc)
            d_force = -axial_factor * (d_force_dm - sweep_angle * force * growth)
        else:
            growth = 1.0
            d_force = 0.0
        torque_arm = (force + lift) * sweep_angle + 2.0 * wr * (
            math.cos(top_inc) - math.cos(bottom_inc))
        d_mu = lam_force * d_force + lam_torque * torque_factor * radius * torque_arm
        return lam_force * growth + lam_torque * mu_torque * radius * sweep_angle, d_mu
    growth = math.exp(mu_axial * theta)
    sign = 1.0 if force >= 0.0 else -1.0
    d_mu = (lam_force * axial_factor * theta * force * growth
            + lam_torque * torque_factor * radius * abs(force) * theta)
    return lam_force * growth + lam_torque * mu_torque * radius * sign * theta, d_mu


@njit(cache=True)
def march_gradient(well_real, well_index, method, mu, bit_depth, bit_force, bit_torque,
                   axial_factor, torque_factor, force_seed, torque_seed):
    """`march` of one operation with the gradient of ``force_seed F_top + torque_seed T_top``.

    The operation's terms are scalars here (`march` takes arrays of them). Returns (top force,
    top torque, gradient per element of ``mu``); elements the string does not reach get 0. One
    forward march and one backward sweep over its pieces (soft string) or runs (Aadnoy). The
    forward loop is `march`'s, written out again because a helper taking the geometry arrays
    costs more per piece than the piece's physics; tests compare the values with `march`'s bit
    for bit.
    """
    well = _unpack(well_real, well_index)
    node_md = well.node_md
    tangents = well.tangents
    dogleg = well.dogleg
    el_kk = well.element_kk
    el_ke = well.element_ke
    el_ee = well.element_ee
    el_dtvd = well.element_dtvd
    curve_kind = well.curve_kind
    run_break = well.run_break
    comp_top = well.component_top
    comp_weight = well.component_weight
    comp_radius = well.component_radius
    n_comp = comp_top.size
    size = node_md.size + n_comp
    # per piece: element, component, force at its bottom; soft string: (kk, ke, ee, dtvd),
    # Aadnoy: its length in column 0
    piece_element = np.empty(size, dtype=np.int64)
    piece_comp = np.empty(size, dtype=np.int64)
    piece_force = np.empty(size)
    piece_values = np.empty((size, 4))
    # per Aadnoy run: first piece, curve kind, component, force at its bottom, and
    # (top inclination, bottom inclination, length, dogleg, friction)
    run_first = np.empty(size + 1, dtype=np.int64)
    run_kind = np.empty(size, dtype=np.int64)
    run_comp = np.empty(size, dtype=np.int64)
    run_force = np.empty(size)
    run_values = np.empty((size, 5))
    j = min(max(np.searchsorted(node_md, bit_depth) - 1, 0), node_md.size - 2)
    comp = 0
    lower = bit_depth
    tb = _tangent_at(node_md, tangents, dogleg, j, lower)
    force = bit_force
    torque = bit_torque
    run_md = lower
    run_tan = tb
    run_mu_length = 0.0
    n = 0
    n_runs = 0
    run_first[0] = 0
    while True:
        element_top = node_md[j]
        component_top = bit_depth - comp_top[comp]
        while comp < n_comp - 1 and component_top >= lower - _MD_TOLERANCE:
            comp += 1
            component_top = bit_depth - comp_top[comp]
        at_component_top = comp < n_comp - 1 and component_top > element_top + _MD_TOLERANCE
        if at_component_top:
            upper = component_top
            tt = _tangent_at(node_md, tangents, dogleg, j, upper)
        else:
            upper = element_top
            tt = (tangents[j, 0], tangents[j, 1], tangents[j, 2])
        length = lower - upper
        piece_element[n] = j
        piece_comp[n] = comp
        piece_force[n] = force
        if method == SOFT_STRING:
            if at_component_top or lower < node_md[j + 1]:
                kk, ke, ee, dtvd = piece_geometry(tt, tb, length)
            else:
                kk, ke, ee, dtvd = el_kk[j], el_ke[j], el_ee[j], el_dtvd[j]
            piece_values[n, 0] = kk
            piece_values[n, 1] = ke
            piece_values[n, 2] = ee
            piece_values[n, 3] = dtvd
            force, normal = _soft_string_piece(force, kk, ke, ee, dtvd, comp_weight[comp],
                                               axial_factor * mu[j])
            torque += torque_factor * mu[j] * normal * comp_radius[comp]
        else:
            run_mu_length += mu[j] * length
            piece_values[n, 0] = length
            component_ends = comp < n_comp - 1 and component_top >= upper - _MD_TOLERANCE
            at_node = not at_component_top
            if component_ends or (at_node and (run_break[j] or j == 0)):
                run_length = run_md - upper
                run_mu = run_mu_length / run_length
                bottom_inc = _inclination(run_tan[0], run_tan[1], run_tan[2])
                top_inc = _inclination(tt[0], tt[1], tt[2])
                theta = _angle_between(tt[0], tt[1], tt[2], run_tan[0], run_tan[1],
                                       run_tan[2])
                run_kind[n_runs] = curve_kind[j]
                run_comp[n_runs] = comp
                run_force[n_runs] = force
                run_values[n_runs, 0] = top_inc
                run_values[n_runs, 1] = bottom_inc
                run_values[n_runs, 2] = run_length
                run_values[n_runs, 3] = theta
                run_values[n_runs, 4] = run_mu
                force, torque = _aadnoy_run(force, torque, top_inc, bottom_inc, run_length,
                                            theta, curve_kind[j], run_mu, axial_factor,
                                            torque_factor, comp_weight[comp], comp_radius[comp])
                n_runs += 1
                run_first[n_runs] = n + 1
                run_md = upper
                run_tan = tt
                run_mu_length = 0.0
        n += 1
        lower = upper
        tb = tt
        if at_component_top:
            comp += 1
        elif j == 0:
            break
        else:
            j -= 1
    gradient = np.zeros(mu.size)
    lam_force = force_seed
    if method == SOFT_STRING:
        for p in range(n - 1, -1, -1):
            c = piece_comp[p]
            e = piece_element[p]
            lam_force, d_mu = _soft_string_piece_adjoint(
                piece_force[p], piece_values[p, 0], piece_values[p, 1], piece_values[p, 2],
                piece_values[p, 3], comp_weight[c], comp_radius[c], mu[e], axial_factor,
                torque_factor, lam_force, torque_seed)
            gradient[e] += d_mu
    else:
        for r in range(n_runs - 1, -1, -1):
            c = run_comp[r]
            lam_force, d_run_mu = _aadnoy_run_adjoint(
                run_force[r], run_values[r, 0], run_values[r, 1], run_values[r, 2],
                run_values[r, 3], run_kind[r], run_values[r, 4], axial_factor, torque_factor,
                comp_weight[c], comp_radius[c], lam_force, torque_seed)
            # the run's friction is the length-weighted mean of its pieces' elements'
            scale = d_run_mu / run_values[r, 2]
            for p in range(run_first[r], run_first[r + 1]):
                gradient[piece_element[p]] += scale * piece_values[p, 0]
    return force, torque, gradient
