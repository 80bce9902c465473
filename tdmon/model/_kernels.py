"""Compiled element loops of the torque-and-drag model (numba).

The physics is documented in `tdmon.model.torque_drag` and docs/torque-drag.md; this module only
holds the loops, written for speed: scalars instead of small arrays, no allocation in the march.

Geometry arrives as the hole grid (node MD, node unit tangents, element dogleg, a curve kind per
element and a run-break flag per node) and the string as cumulative component tops measured from
the bit, with a buoyed weight and a friction radius per component. The march goes from the bit up
to the top of the hole in *pieces*: a piece is the part of a grid element between the bit, the
element's nodes and the string's component boundaries, so each piece has one weight, one radius,
one friction factor and lies on one circular arc.
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit

SOFT_STRING = 0
AADNOY = 1

# element curve kinds (of the survey interval the element lies on)
STRAIGHT = 0
PLANAR_BUILD = 1
GENERAL_CURVE = 2

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
def march(method, node_md, tangents, dogleg, el_kk, el_ke, el_ee, el_dtvd, curve_kind, run_break,
          mu, comp_top, comp_weight, comp_radius, bit_depth, bit_forces, bit_torques,
          axial_factors, torque_factors, record, out_md, out_force, out_torque, out_comp,
          out_tan):
    """March from the bit to the top of the hole for several operations at once.

    An operation is a (bit force, bit torque, axial friction factor, torque friction factor)
    quadruple; the pieces and their geometry are shared by all. Returns (n recorded, top
    forces, top torques). With ``record`` the node MD, component index (of the piece below the
    node) and tangent, and per operation the axial force and torque, are written bit first into
    the ``out_*`` arrays (length >= n elements + n components + 2; out_force and out_torque are
    (n_op, length)). Aadnoy runs write their nodes when the run closes.
    """
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
def sweep(method, node_md, tangents, dogleg, el_kk, el_ke, el_ee, el_dtvd, curve_kind, run_break,
          mu_cases, comp_top, comp_weight, comp_radius, bit_depths, bit_forces, bit_torques,
          axial_factors, torque_factors):
    """Surface force and torque for every (case, depth, operation): arrays (n_case, n_depth, n_op).

    ``mu_cases`` is (n_case, n_element); the operations are marched together (see `march`).
    """
    n_case = mu_cases.shape[0]
    n_depth = bit_depths.size
    n_op = axial_factors.size
    forces = np.empty((n_case, n_depth, n_op))
    torques = np.empty((n_case, n_depth, n_op))
    dummy = np.empty(1)
    dummy_2d = np.empty((1, 1))
    dummy_int = np.empty(1, dtype=np.int64)
    dummy_tan = np.empty((1, 3))
    for c in range(n_case):
        for d in range(n_depth):
            _, f, t = march(method, node_md, tangents, dogleg, el_kk, el_ke, el_ee, el_dtvd,
                            curve_kind, run_break, mu_cases[c], comp_top, comp_weight,
                            comp_radius, bit_depths[d], bit_forces, bit_torques, axial_factors,
                            torque_factors, False, dummy, dummy_2d, dummy_2d, dummy_int,
                            dummy_tan)
            forces[c, d, :] = f
            torques[c, d, :] = t
    return forces, torques
