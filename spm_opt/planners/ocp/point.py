"""The places of an interval where the constraints apply, and the motion at one of them:
the tool's speed, its distance from the planned arc and its progress along it, read from
the segment's arc and the fit of the skull's radius near it.

Lengths are in mm, so that the squared path rows are near 1.
"""

from __future__ import annotations

from collections.abc import Callable
from functools import cached_property

import casadi as ca

from spm_opt.model import kinematics
from spm_opt.skull.arc_fit import ACROSS_DEGREE, ALONG_DEGREE, COEFFICIENTS

ARC_PARAMETERS = 15 + COEFFICIENTS
"""Per segment: the arc's a, w, n, n × end (3 each), and the skull's radius near it
(:mod:`spm_opt.skull.arc_fit`): φ_c, φ_h (rad), o_h, and the coefficients C_kj (mm)."""

NODE, INSIDE, GAUSS, SPEED_CONTROL = "node", "inside", "Gauss point", "speed control point"
"""The places of an interval where constraints apply: the node that starts it, the check
points inside it, its two Gauss–Legendre points, and q̇'s middle Bernstein coefficient."""
GAUSS_FRACTIONS = (0.5 - 3**0.5 / 6, 0.5 + 3**0.5 / 6)
"""The two-point Gauss–Legendre rule's places in an interval, as fractions of it: where the
effort integral and the torque limit read the torque (two table look-ups an interval, and
exact for cubics, as Simpson's three)."""


class Point:
    """The motion at one place of an interval, with the quantities the constraints share
    (SX expressions, built once when first asked for).

    ``arc`` holds the segment's great circle (:data:`ARC_PARAMETERS`, lengths in mm, so
    that the squared path rows are near 1); ``torque`` maps (q, q̇, q̈) to the joint side
    of the actuators' torque (the load's, the drives' inertia and friction), N·m.
    """

    def __init__(self, state: ca.SX, arc: ca.SX, torque: Callable[..., ca.SX]) -> None:
        self.q, self.qd, self.qdd = state[0:2], state[2:4], state[4:6]
        self._arc, self._torque = arc, torque

    @cached_property
    def _geometry(self) -> dict[str, ca.SX]:
        arc = self._arc
        a, w, n, w_end = (arc[3 * k : 3 * k + 3] for k in range(4))
        p = ca.vertcat(*kinematics.direction(self.q[0], self.q[1]))
        d1, d2 = kinematics.direction_jacobian(self.q[0], self.q[1])
        p_dot = ca.vertcat(*d1) * self.qd[0] + ca.vertcat(*d2) * self.qd[1]
        pa, pw = ca.dot(p, a), ca.dot(p, w)
        off_plane = ca.dot(p, n)
        angle_rate = (ca.dot(p_dot, w) * pa - pw * ca.dot(p_dot, a)) / (pa**2 + pw**2)
        on_arc, rho, along_slope, across_slope = _RADIUS(arc[12:], ca.atan2(pw, pa), off_plane)
        rho_rate = along_slope * angle_rate + across_slope * ca.dot(p_dot, n)
        return {
            "tool speed²": ca.sumsqr(p_dot) * rho**2 + rho_rate**2,
            # |ρ p − ρ_c c|², c the point of the arc's plane nearest p (Contour.distance)
            "chord²": (rho - on_arc) ** 2 + 2 * rho * on_arc * (1 - ca.sqrt(1 - off_plane**2)),
            "progress speed": on_arc * angle_rate,
            "past start": pw,
            "before end": -ca.dot(p, w_end),
        }

    def __getitem__(self, name: str) -> ca.SX:
        return self._geometry[name]

    @cached_property
    def torque(self) -> ca.SX:
        """The joint side of the actuators' torque, N·m (2,)."""
        return self._torque(self.q, self.qd, self.qdd)


def _radius_function() -> ca.Function:
    """The skull's radius (mm) near an arc, from its fit's parameters (φ_c, φ_h, o_h, C_kj)
    at the angle φ along it and the off-plane component o: on the arc (o = 0), at the point
    itself, and the latter's partial derivatives in φ and o."""
    fit = ca.SX.sym("fit", 3 + COEFFICIENTS)
    along, off = ca.SX.sym("along"), ca.SX.sym("off")
    x, y = (along - fit[0]) / fit[1], off / fit[2]
    coefficients = fit[3:]
    chebyshev = [1, x]
    for _ in range(ALONG_DEGREE - 1):
        chebyshev.append(2 * x * chebyshev[-1] - chebyshev[-2])
    across = [
        sum(
            chebyshev[k] * coefficients[k * (ACROSS_DEGREE + 1) + j]
            for k in range(ALONG_DEGREE + 1)
        )
        for j in range(ACROSS_DEGREE + 1)
    ]
    rho = sum(term * y**j for j, term in enumerate(across))
    outputs = [across[0], rho, ca.jacobian(rho, along), ca.jacobian(rho, off)]
    return ca.Function("skull_radius", [fit, along, off], outputs)


_RADIUS = _radius_function()
