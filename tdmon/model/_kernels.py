"""The element loops of the torque-and-drag model: plain Python that numba compiles.

The physics is documented in `tdmon.model.torque_drag` and docs/torque-drag.md; this module only
holds the loops, written for speed: scalars instead of small arrays, no allocation in the loops.

Geometry arrives as the hole grid (node MD, node unit tangents, element dogleg, a curve kind per
element and a run-break flag per node) and the string as cumulative component tops measured from
the bit, with a buoyed weight and a friction radius per component. The march goes from the bit up
to the top of the hole in *pieces*: a piece is the part of a grid element between the bit, the
element's nodes and the string's component boundaries, so each piece has one weight, one radius,
one friction factor and lies on one circular arc.

There is one element loop, `_march`, and every entry point runs it: one friction array or
several (*cases*) and one or several operations in one march, with the loads at every node
(`march_profile`) or only at the top, and with a *tape* for the adjoint (`march_gradient`: the
value and its gradient with respect to every element's friction factor). The force terms of a
piece are written once, in `_soft_string_piece` (weight and friction of the soft string) and
`_aadnoy_run` (Aadnoy's closed forms over a run); the adjoint's backward pass reruns
`_soft_string_piece` for the values it differentiates.

The fluid terms (docs/hydraulics.md) are one more argument of `_march`, ``fluid``: an axial
force per metre of every element and operation (the mud's viscous drag on the moving pipe and
the annular flow's, computed outside the loops from the mud and the block speed), added where
the weight enters, ``axial_weight`` in `_soft_string_piece` and with the weight's lift in
`_aadnoy_run`'s closed forms; and the densities outside and inside the string at every element,
which move a piece's buoyed weight (read once, in `_march`: the component's weight plus its
sensitivities times the element's density shifts). In the soft string the axial force adds
nothing to the adjoint's derivatives (it depends on neither the force nor the friction) and the
backward pass gets its values through the rerun piece; `_aadnoy_run_adjoint` takes it where it
takes the weight's lift. The adjoint reads each piece's weight, radius and fluid force from its
tape. Without fluid terms (an empty array, checked once per march) every step is the one of a
march without them, bit for bit.
The bit's force and torque (WOB, bit torque) are the march's starting values, ``bit_forces`` and
``bit_torques``. What a sensor reads of the top force (sheave efficiency, dead-line sensor,
block acceleration) is not the loops' business: `WellModel` adds the block weight to the top
force outside them, and a measurement model belongs there too.

This module imports no numba. `tdmon.model.kernels` runs every function here either compiled
by numba (``njit(cache=True)``) or as it is, plain Python, with the same numbers bit for bit:
so the code keeps to what both do alike (math functions, float64 and int64 arrays indexed by
scalars, no fast-math, ``None`` for an absent profile or tape, which numba compiles away).
The per-well arrays travel packed in two flat buffers (built once per well by `pack_well`); the
entry points take them and the per-call values, positionally or by keyword.
"""

from __future__ import annotations

import math
from collections import namedtuple

import numpy as np

# the methods, as the model passes them
SOFT_STRING = 0
AADNOY = 1

# element curve kinds (of the survey interval the element lies on)
STRAIGHT = 0
PLANAR_BUILD = 1
GENERAL_CURVE = 2

_STRAIGHT_DOGLEG = 1e-7
_MD_TOLERANCE = 1e-9


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


def _angle_between(ax, ay, az, bx, by, bz):
    """Angle between two unit vectors, accurate for small angles."""
    dx = bx - ax
    dy = by - ay
    dz = bz - az
    half_chord = 0.5 * math.sqrt(dx * dx + dy * dy + dz * dz)
    if half_chord > 1.0:
        half_chord = 1.0
    return 2.0 * math.asin(half_chord)


def _inclination(x, y, z):
    return math.atan2(math.sqrt(x * x + y * y), z)


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
# Two flat buffers rather than twelve arrays: numba's dispatcher unboxes every array argument
# on each call (about 0.05 us each). The entry points unpack the buffers into `_WellArrays`,
# views the loops read by name.

_WellArrays = namedtuple("_WellArrays", [
    "node_md", "tangents", "dogleg", "curve_kind", "run_break", "element_kk", "element_ke",
    "element_ee", "element_dtvd", "component_top", "component_weight", "component_radius",
    "component_outside_sensitivity", "component_inside_sensitivity"])

# the index buffer starts with the sizes: nodes, elements, components
_HEADER = 3


def pack_well(node_md, tangents, dogleg, curve_kind, run_break, component_top,
              component_weight, component_radius, component_outside_sensitivity,
              component_inside_sensitivity):
    """Pack a well's arrays into the two buffers every entry point takes, and add the whole
    elements' `piece_geometry`.

    Hole grid: ``node_md`` (n_nodes,) [m], ``tangents`` (n_nodes, 3) unit tangents [-],
    ``dogleg`` (n_elements,) [rad], ``curve_kind`` (n_elements,) (`STRAIGHT`, `PLANAR_BUILD`,
    `GENERAL_CURVE`), ``run_break`` (n_nodes,) where an Aadnoy run ends. String, bit first:
    ``component_top`` (n_components,) cumulative top from the bit [m], ``component_weight``
    buoyed weight per length [N/m], ``component_radius`` friction radius of the torque [m],
    ``component_outside_sensitivity`` and ``component_inside_sensitivity`` the change of the
    buoyed weight per unit of the fluid density outside and inside [N/m per kg/m^3] (what a
    per-element density in a march's fluid terms changes; 0 for a weight given buoyed).
    Every array C-contiguous, float64 but ``curve_kind`` (int64) and ``run_break`` (bool).

    Returns ``(real, index)``: float64 node MD, tangents, dogleg, the elements' kk, ke, ee,
    dtvd and the five component arrays, in this order; int64 sizes (`_HEADER`), curve kinds
    and run breaks (0 or 1).
    """
    n_nodes = node_md.size
    n_elements = dogleg.size
    n_components = component_top.size
    real = np.empty(4 * n_nodes + 5 * n_elements + 5 * n_components)
    index = np.empty(_HEADER + n_elements + n_nodes, dtype=np.int64)
    index[0] = n_nodes
    index[1] = n_elements
    index[2] = n_components
    kk, ke, ee, dtvd = element_geometry(node_md, tangents)
    at = 0
    for part in (node_md, tangents.ravel(), dogleg, kk, ke, ee, dtvd, component_top,
                 component_weight, component_radius, component_outside_sensitivity,
                 component_inside_sensitivity):
        real[at:at + part.size] = part
        at += part.size
    index[_HEADER:_HEADER + n_elements] = curve_kind
    for i in range(n_nodes):
        index[_HEADER + n_elements + i] = 1 if run_break[i] else 0
    return real, index


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
        real[c + n_comp:c + 2 * n_comp], real[c + 2 * n_comp:c + 3 * n_comp],
        real[c + 3 * n_comp:c + 4 * n_comp], real[c + 4 * n_comp:c + 5 * n_comp])


def all_finite_non_negative(values):
    """Whether every value of a 1-D array is finite and >= 0 (friction checks: one compiled
    pass instead of two numpy reductions, each of which costs about 1 us on a short array)."""
    for v in values:  # noqa: SIM110 (a loop: numba does not compile all() of a generator)
        if not (v >= 0.0 and v < math.inf):  # NaN fails both
            return False
    return True


# --- the force terms of a piece (soft string) and of a run (Aadnoy) ---


def _normal_force(force, weight, kk, ke, ee):
    squared = force * force * kk + 2.0 * force * weight * ke + weight * weight * ee
    return math.sqrt(squared) if squared > 0.0 else 0.0


def _soft_string_piece(force, kk, ke, ee, dtvd, weight, axial_mu, fluid):
    """One piece of the 3D soft-string march: returns (force at the top, normal force, and the
    two intermediate values the adjoint needs: the normal force at the bottom, the predicted
    force at the top).

    ``fluid`` is the piece's axial fluid force [N] (tension positive at the top: the viscous
    drag of the mud on the moving pipe), added to the weight's axial part; it bends nothing, so
    it is not in the contact force's weight term. Exactly 0.0 adds nothing, not even a
    rounding: the march without fluid terms is the march of before, bit for bit.

    The contact force is ``N = |F (t_b - t_t) + W (e_z - (e_z . t_m) t_m)|``, the vector form of
    Johancsik's ``sqrt((F dphi sin a)^2 + (F da + W sin a)^2)`` with ``da = a_top - a_bottom``;
    the vector form needs no sign convention and no azimuth wrapping. The force entering N is
    averaged over the piece (Heun's predictor-corrector) rather than taken at the bottom.
    """
    axial_weight = weight * dtvd
    if fluid != 0.0:
        axial_weight += fluid
    n_bottom = _normal_force(force, weight, kk, ke, ee)
    predicted = force + axial_weight + axial_mu * n_bottom
    n_top = _normal_force(predicted, weight, kk, ke, ee)
    normal = 0.5 * (n_bottom + n_top)
    return force + axial_weight + axial_mu * normal, normal, n_bottom, predicted


def _run_geometry(top, bottom):
    """What Aadnoy's closed forms read of a run's ends (unit tangents ``top``, ``bottom``):
    (top inclination, bottom inclination, dogleg [rad], and for a straight run the cosine and
    sine of the mean inclination, else 0.0 and 0.0). The same for every case and operation."""
    bottom_inc = _inclination(bottom[0], bottom[1], bottom[2])
    top_inc = _inclination(top[0], top[1], top[2])
    theta = _angle_between(top[0], top[1], top[2], bottom[0], bottom[1], bottom[2])
    if theta < _STRAIGHT_DOGLEG:
        mean_inc = 0.5 * (top_inc + bottom_inc)
        return top_inc, bottom_inc, theta, math.cos(mean_inc), math.sin(mean_inc)
    return top_inc, bottom_inc, theta, 0.0, 0.0


def _aadnoy_run(force, torque, geometry, length, kind, mu, axial_factor, torque_factor, weight,
                radius, fluid):
    """Closed-form step over one run (arc or straight) as Aadnoy publishes it; ``geometry`` is
    `_run_geometry`'s.

    Straight: eq 42 and eq 45 of the thesis. Planar build (inclination rising with depth):
    Tables 20-22 of the thesis, generalised from (0, alpha) to (a_top, a_bottom). Any other arc:
    Aadnoy, Fazaelizadeh and Hareland (2010), tension dominated.

    ``fluid``, the run's axial fluid force [N], goes where the formulas take the weight's
    lift: next to ``w L cos a`` on a straight run and to the lift of the 2010 arc formula (not
    amplified), and into the lift of the build formulas, i.e. onto the run's bottom force,
    which the capstan factor amplifies (the slack-off formula has no lift of its own: the fluid
    force joins the bottom force there too). Exactly 0.0 adds nothing.
    """
    top_inc, bottom_inc, theta, cos_mean, sin_mean = geometry
    mu_axial = axial_factor * mu
    mu_torque = torque_factor * mu
    if theta < _STRAIGHT_DOGLEG:
        new_force = force + weight * length * (cos_mean + mu_axial * sin_mean)
        if fluid != 0.0:
            new_force += fluid
        new_torque = torque + mu_torque * weight * length * radius * sin_mean
        return new_force, new_torque
    if kind == PLANAR_BUILD and bottom_inc > top_inc:
        if fluid != 0.0:
            force = force + fluid
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
    if fluid != 0.0:
        lift += fluid
    new_force = force * math.exp(mu_axial * theta) + lift
    new_torque = torque + mu_torque * radius * abs(force) * theta
    return new_force, new_torque


# --- the element loop ---
#
# What a march writes besides the top loads, when asked (None otherwise):
# - a profile: per recorded node (bit first) its MD, the index of the component below it, its
#   unit tangent, and per (case, operation) the axial force and torque there;
# - a tape, for the adjoint of one case and one operation: per piece its element, the force at
#   its bottom and (kk, ke, ee, dtvd, weight, radius, fluid force) for the soft string or its
#   length in column 0 for Aadnoy; per Aadnoy run its first piece (and, after the last run,
#   one past the last piece), curve kind, the force at its bottom and (top inclination, bottom
#   inclination, dogleg, cosine and sine of the mean inclination, length, friction, weight,
#   radius, fluid force). The backward pass reads what the forward pass used from the tape.
#
# The fluid terms of a march (docs/hydraulics.md) arrive as one array ``fluid``: empty (0, 0)
# when there are none, else (n_op + 2, n_elements): per operation the axial fluid force per
# metre of every element [N/m] (tension positive at the top), then the shift of the density
# outside and inside the string at every element from the well's fluid [kg/m^3], which moves
# a piece's buoyed weight by the component's sensitivities. Whether there are any is read
# once per march; without them every piece takes the steps of a march without fluid terms.

_Profile = namedtuple("_Profile", ["md", "component", "tangent", "force", "torque"])
_Tape = namedtuple("_Tape", [
    "piece_element", "piece_force", "piece_values", "run_first", "run_kind", "run_force",
    "run_values"])

NO_FLUID = np.empty((0, 0))
"""The fluid terms of a march without any (see the comment above)."""


def _record(profile, k, md, comp, tangent, forces, torques):
    profile.md[k] = md
    profile.component[k] = comp
    profile.tangent[k, 0] = tangent[0]
    profile.tangent[k, 1] = tangent[1]
    profile.tangent[k, 2] = tangent[2]
    for c in range(forces.shape[0]):
        for o in range(forces.shape[1]):
            profile.force[c, o, k] = forces[c, o]
            profile.torque[c, o, k] = torques[c, o]


def _record_run(profile, first, last, run_force, run_torque, run_md, run_tan, run_mu_length,
                run_length, kind, axial_factors, torque_factors, weight, radius, run_fluid):
    """The loads at the nodes ``first`` to ``last - 1`` recorded inside a closed Aadnoy run:
    the run's closed form from its bottom state to each node, with the whole run's friction
    and its fluid force per metre."""
    for i in range(first, last):
        node_tan = (profile.tangent[i, 0], profile.tangent[i, 1], profile.tangent[i, 2])
        geometry = _run_geometry(node_tan, run_tan)
        part = run_md - profile.md[i]
        for c in range(run_force.shape[0]):
            run_mu = run_mu_length[c] / run_length
            for o in range(run_force.shape[1]):
                fluid = run_fluid[o]
                if fluid != 0.0:
                    fluid = fluid * part / run_length
                profile.force[c, o, i], profile.torque[c, o, i] = _aadnoy_run(
                    run_force[c, o], run_torque[c, o], geometry, part, kind,
                    run_mu, axial_factors[o], torque_factors[o], weight, radius, fluid)


def _march(well, method, mu_cases, bit_depth, bit_forces, bit_torques, axial_factors,  # noqa: C901  (the one element loop, one compiled body)
           torque_factors, fluid, forces, torques, profile, tape):
    """March from the bit to the top of the hole for every (case, operation) at once.

    An operation is a (bit force, bit torque, axial friction factor, torque friction factor)
    quadruple, a case a friction array ``mu_cases[c]`` (one value per element). The pieces,
    their geometry and the Aadnoy runs depend on the bit depth only, so they are found once
    for all; each (case, operation) then takes the same steps in the same order as it would
    alone, and gets the same numbers bit for bit. The cases are independent chains of square
    roots and divisions, which the processor overlaps: that, and the shared geometry, is why
    several cost little more than one. ``fluid`` holds the march's fluid terms (see above).

    Writes the top force and torque of every (case, operation) into ``forces`` and ``torques``
    (n_case, n_op), and the ``profile`` and the ``tape`` (see above) unless they are None.
    Returns the numbers of nodes recorded, pieces marched and Aadnoy runs taped.

    The walk from piece to piece and the steps over the cases are written out here, not in
    helpers: numba does not inline a helper that takes the well's or the cases' arrays, and
    the call per piece made the 6000-element march four times slower (tried).
    """
    node_md = well.node_md
    tangents = well.tangents
    dogleg = well.dogleg
    comp_top = well.component_top
    n_comp = comp_top.size
    n_case, n_op = forces.shape
    with_fluid = fluid.shape[0] > 0
    j = min(max(np.searchsorted(node_md, bit_depth) - 1, 0), node_md.size - 2)
    comp = 0
    lower = bit_depth
    tb = _tangent_at(node_md, tangents, dogleg, j, lower)
    for c in range(n_case):
        for o in range(n_op):
            forces[c, o] = bit_forces[o]
            torques[c, o] = bit_torques[o]
    k = 0  # nodes recorded
    if profile is not None:
        _record(profile, k, lower, comp, tb, forces, torques)
        k += 1
    n = 0  # pieces marched
    n_runs = 0
    # Aadnoy runs: the state at the run's bottom, each case's length-weighted friction and,
    # with fluid terms, each operation's fluid force and the length-weighted shift of the
    # weight (a run is one component: its weight plus the mean shift)
    run_force = forces.copy()
    run_torque = torques.copy()
    run_mu_length = np.zeros(n_case)
    run_fluid = np.zeros(n_op)
    run_shift_length = 0.0
    run_md = lower
    run_tan = tb
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
        weight = well.component_weight[comp]
        shift = 0.0  # of the weight, by the densities
        if with_fluid:
            shift = (well.component_outside_sensitivity[comp] * fluid[n_op, j]
                     + well.component_inside_sensitivity[comp] * fluid[n_op + 1, j])
            weight += shift
        radius = well.component_radius[comp]
        if tape is not None:
            tape.piece_element[n] = j
            tape.piece_force[n] = forces[0, 0]
        if method == SOFT_STRING:
            if at_component_top or lower < node_md[j + 1]:
                kk, ke, ee, dtvd = piece_geometry(tt, tb, length)
            else:
                kk = well.element_kk[j]
                ke = well.element_ke[j]
                ee = well.element_ee[j]
                dtvd = well.element_dtvd[j]
            if tape is not None:
                tape.piece_values[n, 0] = kk
                tape.piece_values[n, 1] = ke
                tape.piece_values[n, 2] = ee
                tape.piece_values[n, 3] = dtvd
                tape.piece_values[n, 4] = weight
                tape.piece_values[n, 5] = radius
                tape.piece_values[n, 6] = fluid[0, j] * length if with_fluid else 0.0
            for c in range(n_case):
                mu = mu_cases[c, j]
                for o in range(n_op):
                    piece_fluid = fluid[o, j] * length if with_fluid else 0.0
                    forces[c, o], normal, _, _ = _soft_string_piece(
                        forces[c, o], kk, ke, ee, dtvd, weight, axial_factors[o] * mu,
                        piece_fluid)
                    torques[c, o] += torque_factors[o] * mu * normal * radius
        else:
            for c in range(n_case):
                run_mu_length[c] += mu_cases[c, j] * length
            if with_fluid:
                for o in range(n_op):
                    run_fluid[o] += fluid[o, j] * length
                run_shift_length += shift * length
            if tape is not None:
                tape.piece_values[n, 0] = length
            component_ends = comp < n_comp - 1 and component_top >= upper - _MD_TOLERANCE
            at_node = not at_component_top
            if component_ends or (at_node and (well.run_break[j] or j == 0)):
                geometry = _run_geometry(tt, run_tan)
                run_length = run_md - upper
                kind = well.curve_kind[j]
                if with_fluid:
                    weight = well.component_weight[comp] + run_shift_length / run_length
                if profile is not None:
                    _record_run(profile, run_first, k, run_force, run_torque, run_md, run_tan,
                                run_mu_length, run_length, kind, axial_factors, torque_factors,
                                weight, radius, run_fluid)
                if tape is not None:
                    _tape_run(tape, n_runs, n, kind, run_force[0, 0], geometry, run_length,
                              run_mu_length[0] / run_length, weight, radius, run_fluid[0])
                    n_runs += 1
                for c in range(n_case):
                    run_mu = run_mu_length[c] / run_length
                    for o in range(n_op):
                        forces[c, o], torques[c, o] = _aadnoy_run(
                            run_force[c, o], run_torque[c, o], geometry, run_length, kind,
                            run_mu, axial_factors[o], torque_factors[o], weight, radius,
                            run_fluid[o])
                        run_force[c, o] = forces[c, o]
                        run_torque[c, o] = torques[c, o]
                    run_mu_length[c] = 0.0
                for o in range(n_op):
                    run_fluid[o] = 0.0
                run_shift_length = 0.0
                run_md = upper
                run_tan = tt
                run_first = k + 1
        if profile is not None:  # inside an Aadnoy run: the run's bottom loads until it closes
            _record(profile, k, upper, comp, tt, forces, torques)
            k += 1
        n += 1
        lower = upper
        tb = tt
        if at_component_top:
            comp += 1
        elif j == 0:
            break
        else:
            j -= 1
    return k, n, n_runs


def _tape_run(tape, r, last_piece, kind, bottom_force, geometry, length, mu, weight, radius,
              fluid):
    """Keep run ``r`` (its last piece ``last_piece``) on the tape."""
    tape.run_first[r + 1] = last_piece + 1
    tape.run_kind[r] = kind
    tape.run_force[r] = bottom_force
    top_inc, bottom_inc, theta, cos_mean, sin_mean = geometry
    tape.run_values[r, 0] = top_inc
    tape.run_values[r, 1] = bottom_inc
    tape.run_values[r, 2] = theta
    tape.run_values[r, 3] = cos_mean
    tape.run_values[r, 4] = sin_mean
    tape.run_values[r, 5] = length
    tape.run_values[r, 6] = mu
    tape.run_values[r, 7] = weight
    tape.run_values[r, 8] = radius
    tape.run_values[r, 9] = fluid


# --- the entry points ---


def march_one(well_real, well_index, method, mu, bit_depth, bit_force, bit_torque, axial_factor,
              torque_factor, fluid):
    """The march of one operation and one friction array ``mu`` (n_elements,) [-], as two
    floats: (top force [N], top torque [N m]).

    ``method`` is `SOFT_STRING` or `AADNOY`; ``bit_depth`` [m] lies inside the string and the
    hole; the operation is its force [N] and torque [N m] at the bit and the multipliers of mu in
    the axial and the torque balance [-]; ``fluid`` its fluid terms (`NO_FLUID`, or
    (3, n_elements): see the element loop's notes). Scalars in, scalars out: this keeps the
    call's fixed cost low (the calibration makes thousands).
    """
    forces = np.empty((1, 1))
    torques = np.empty((1, 1))
    _march(_unpack(well_real, well_index), method, mu.reshape((1, mu.size)), bit_depth,
           np.full(1, bit_force), np.full(1, bit_torque), np.full(1, axial_factor),
           np.full(1, torque_factor), fluid, forces, torques, None, None)
    return forces[0, 0], torques[0, 0]


def march_cases(well_real, well_index, method, mu_cases, bit_depth, bit_forces, bit_torques,
                axial_factors, torque_factors, fluid):
    """The march of several friction cases and operations at once: arrays (n_case, n_op) of
    the top forces [N] and torques [N m]; ``mu_cases`` is (n_case, n_elements), C-contiguous
    [-], the operations' terms (n_op,) each, as `march_one`'s, ``fluid`` `NO_FLUID` or
    (n_op + 2, n_elements)."""
    forces = np.empty((mu_cases.shape[0], bit_forces.size))
    torques = np.empty((mu_cases.shape[0], bit_forces.size))
    _march(_unpack(well_real, well_index), method, mu_cases, bit_depth, bit_forces, bit_torques,
           axial_factors, torque_factors, fluid, forces, torques, None, None)
    return forces, torques


def march_profile(well_real, well_index, method, mu, bit_depth, bit_forces, bit_torques,
                  axial_factors, torque_factors, fluid, out_md, out_force, out_torque, out_comp,
                  out_tan):
    """The march of one friction array that also writes the loads at every node, bit first;
    returns the node count.

    The outputs have room for n_elements + n_components + 2 nodes: ``out_md`` [m],
    ``out_comp`` (index of the component below the node), ``out_tan`` (n, 3) unit tangent,
    and per operation ``out_force`` [N] and ``out_torque`` [N m], (n_op, n), C-contiguous.
    """
    n_op, size = out_force.shape
    profile = _Profile(out_md, out_comp, out_tan, out_force.reshape((1, n_op, size)),
                       out_torque.reshape((1, n_op, size)))
    count, _, _ = _march(_unpack(well_real, well_index), method, mu.reshape((1, mu.size)),
                         bit_depth, bit_forces, bit_torques, axial_factors, torque_factors,
                         fluid, np.empty((1, n_op)), np.empty((1, n_op)), profile, None)
    return count


def sweep(well_real, well_index, method, mu_cases, bit_depths, bit_forces, bit_torques,
          axial_factors, torque_factors):
    """Surface force and torque for every (case, depth, operation): arrays (n_case, n_depth, n_op).

    ``mu_cases`` is (n_case, n_element); the other arguments are `march_cases`'. No fluid
    terms: they depend on the bit depth (a broomstick with them marches depth by depth).
    """
    n_case = mu_cases.shape[0]
    n_depth = bit_depths.size
    n_op = axial_factors.size
    forces = np.empty((n_case, n_depth, n_op))
    torques = np.empty((n_case, n_depth, n_op))
    top_forces = np.empty((n_case, n_op))
    top_torques = np.empty((n_case, n_op))
    well = _unpack(well_real, well_index)
    no_fluid = np.empty((0, 0))
    for d in range(n_depth):
        _march(well, method, mu_cases, bit_depths[d], bit_forces, bit_torques, axial_factors,
               torque_factors, no_fluid, top_forces, top_torques, None, None)
        forces[:, d, :] = top_forces
        torques[:, d, :] = top_torques
    return forces, torques


# --- adjoint: the march's value and its gradient with respect to every element's friction ---
#
# One operation, one output ``q = force_seed * F_top + torque_seed * T_top``. The forward pass
# is `_march` with a tape (the same steps, so the value is the march's to the bit): the state at
# the bottom of each piece (soft string) or run (Aadnoy) and their geometry. The backward pass
# carries the adjoints ``lam_F = dq/dF`` and ``lam_T = dq/dT`` from the top down to the bit and
# adds each piece's or run's ``dq/dmu`` to its element. Where the march has a kink (the contact
# force at N = 0, |F| in Aadnoy's torque) the derivative is that of the branch the forward pass
# took.


def _normal_force_slope(force, weight, kk, ke, ee):
    """dN/dF of `_normal_force` (0 where the forward pass clips N to 0)."""
    squared = force * force * kk + 2.0 * force * weight * ke + weight * weight * ee
    if squared > 0.0:
        return (force * kk + weight * ke) / math.sqrt(squared)
    return 0.0


def _soft_string_piece_adjoint(force, kk, ke, ee, dtvd, weight, radius, fluid, mu, axial_factor,
                               torque_factor, lam_force, lam_torque):
    """Backward step over one `_soft_string_piece`: from the adjoints at the piece's top and the
    force at its bottom, returns (adjoint of the bottom force, dq/dmu of the piece). The
    piece's fluid force depends on neither the force nor the friction: it only moves the
    values the rerun piece gives."""
    axial_mu = axial_factor * mu
    _, normal, n_bottom, predicted = _soft_string_piece(force, kk, ke, ee, dtvd, weight,
                                                        axial_mu, fluid)
    lam_normal = lam_force * axial_mu + lam_torque * torque_factor * mu * radius
    lam_predicted = 0.5 * lam_normal * _normal_force_slope(predicted, weight, kk, ke, ee)
    lam_n_bottom = 0.5 * lam_normal + lam_predicted * axial_mu
    d_mu = ((lam_force * axial_factor + lam_torque * torque_factor * radius) * normal
            + lam_predicted * axial_factor * n_bottom)
    lam_bottom = (lam_force + lam_predicted
                  + lam_n_bottom * _normal_force_slope(force, weight, kk, ke, ee))
    return lam_bottom, d_mu


def _slack_off_k(a, weight_radius, m):
    """``K(a) = w R ((1 - m^2) sin a - 2 m cos a) / (1 + m^2)`` of the slack-off build formula
    and its derivative in m."""
    q = 1.0 + m * m
    g = (1.0 - m * m) * math.sin(a) - 2.0 * m * math.cos(a)
    dg = -2.0 * m * math.sin(a) - 2.0 * math.cos(a)
    return weight_radius * g / q, weight_radius * (dg * q - 2.0 * m * g) / (q * q)


def _build_slack_off_term(sweep_angle, weight_radius, m, top_inc, bottom_inc):
    """d/dm of ``K(a2) e^(-m s) - K(a1)`` in the slack-off build formula (the part of dF2/dm
    without F1); returns (that, e^(-m s))."""
    decay = math.exp(-m * sweep_angle)
    k_bottom, dk_bottom = _slack_off_k(bottom_inc, weight_radius, m)
    _, dk_top = _slack_off_k(top_inc, weight_radius, m)
    return dk_bottom * decay - sweep_angle * k_bottom * decay - dk_top, decay


def _aadnoy_run_adjoint(force, geometry, length, kind, mu, axial_factor, torque_factor, weight,
                        radius, fluid, lam_force, lam_torque):
    """Backward step over one `_aadnoy_run` (same branches): from the adjoints at the run's
    top and the force at its bottom, returns (adjoint of the bottom force, dq/d(run friction)).
    The bottom torque's adjoint is the top's (torque adds). The run's fluid force enters the
    build formulas with the bottom force, as in `_aadnoy_run`, and nothing else."""
    top_inc, bottom_inc, theta, _, sin_mean = geometry
    mu_axial = axial_factor * mu
    mu_torque = torque_factor * mu
    if theta < _STRAIGHT_DOGLEG:
        d_mu = (lam_force * axial_factor * weight * length * sin_mean
                + lam_torque * torque_factor * weight * length * radius * sin_mean)
        return lam_force, d_mu
    if kind == PLANAR_BUILD and bottom_inc > top_inc:
        if fluid != 0.0:
            force = force + fluid
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


def march_gradient(well_real, well_index, method, mu, bit_depth, bit_force, bit_torque,
                   axial_factor, torque_factor, fluid, force_seed, torque_seed):
    """`march_one` (its ``fluid`` too) with the gradient of ``force_seed F_top + torque_seed
    T_top``.

    Returns (top force, top torque, gradient per element of ``mu``); elements the string does
    not reach get 0. One forward march with a tape and one backward sweep over its pieces (soft
    string) or runs (Aadnoy).
    """
    well = _unpack(well_real, well_index)
    size = well.node_md.size + well.component_top.size  # more than the pieces
    tape = _Tape(np.empty(size, dtype=np.int64), np.empty(size), np.empty((size, 7)),
                 np.zeros(size + 1, dtype=np.int64), np.empty(size, dtype=np.int64),
                 np.empty(size), np.empty((size, 10)))
    forces = np.empty((1, 1))
    torques = np.empty((1, 1))
    _, n_pieces, n_runs = _march(
        well, method, mu.reshape((1, mu.size)), bit_depth, np.full(1, bit_force),
        np.full(1, bit_torque), np.full(1, axial_factor), np.full(1, torque_factor), fluid,
        forces, torques, None, tape)
    gradient = np.zeros(mu.size)
    lam_force = force_seed
    if method == SOFT_STRING:
        pieces = tape.piece_values
        for p in range(n_pieces - 1, -1, -1):
            e = tape.piece_element[p]
            lam_force, d_mu = _soft_string_piece_adjoint(
                tape.piece_force[p], pieces[p, 0], pieces[p, 1], pieces[p, 2], pieces[p, 3],
                pieces[p, 4], pieces[p, 5], pieces[p, 6], mu[e], axial_factor, torque_factor,
                lam_force, torque_seed)
            gradient[e] += d_mu
    else:
        runs = tape.run_values
        for r in range(n_runs - 1, -1, -1):
            geometry = (runs[r, 0], runs[r, 1], runs[r, 2], runs[r, 3], runs[r, 4])
            lam_force, d_run_mu = _aadnoy_run_adjoint(
                tape.run_force[r], geometry, runs[r, 5], tape.run_kind[r], runs[r, 6],
                axial_factor, torque_factor, runs[r, 7], runs[r, 8], runs[r, 9], lam_force,
                torque_seed)
            # the run's friction is the length-weighted mean of its pieces' elements'
            scale = d_run_mu / runs[r, 5]
            for p in range(tape.run_first[r], tape.run_first[r + 1]):
                gradient[tape.piece_element[p]] += scale * tape.piece_values[p, 0]
    return forces[0, 0], torques[0, 0], gradient
