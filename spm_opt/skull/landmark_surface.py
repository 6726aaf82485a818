"""Without a mesh: a smooth surface through the landmarks.

The radius in a direction p (a unit vector) is a cubic radial basis interpolant with a
linear part in the tangent plane at the landmarks' mean direction m:

    ρ(p) = Σ_i w_i |p − p_i|³ + c₀ + c₁ (p · e₁) + c₂ (p · e₂),

with p_i the landmarks' directions and e₁, e₂ ⟂ m. It passes through every landmark, is
twice continuously differentiable (no jump where the nearest arc changes at a corner), and
is constant on a flap whose landmarks lie on one sphere. The linear part in tangent
coordinates, not in x, y, z, keeps the system well conditioned on a small cap, where z is
nearly 1 for every landmark.
"""

from __future__ import annotations

import numpy as np


class LandmarkSurface:
    """The smooth surface through landmarks (n, 3), m (see the module's docstring)."""

    def __init__(self, landmarks: np.ndarray) -> None:
        landmarks = np.asarray(landmarks, dtype=float)
        radii = np.linalg.norm(landmarks, axis=1)
        self.centres = landmarks / radii[:, None]
        mean = self.centres.mean(axis=0)
        mean /= np.linalg.norm(mean)
        helper = np.eye(3)[np.argmin(np.abs(mean))]
        first = np.cross(mean, helper)
        first /= np.linalg.norm(first)
        self.tangents = np.stack([first, np.cross(mean, first)])
        """e₁, e₂ (2, 3): the tangent plane's axes at the landmarks' mean direction."""
        n = len(landmarks)
        kernel = np.linalg.norm(self.centres[:, None, :] - self.centres, axis=2) ** 3
        linear = self._linear_basis(self.centres)
        system = np.zeros((n + 3, n + 3))
        system[:n, :n], system[:n, n:], system[n:, :n] = kernel, linear, linear.T
        rhs = np.concatenate([radii, np.zeros(3)])
        # least squares: with two landmarks (or three on one great circle) the linear part
        # is not determined, and the smallest solution still passes through every landmark
        solution = np.linalg.lstsq(system, rhs, rcond=None)[0]
        self.weights, self.linear = solution[:n], solution[n:]

    def _linear_basis(self, p: np.ndarray) -> np.ndarray:
        return np.column_stack([np.ones(len(p)), p @ self.tangents.T])

    def radius(self, directions: np.ndarray) -> np.ndarray:
        """Radius (N,), m, of the surface along unit directions (N, 3)."""
        p = np.atleast_2d(np.asarray(directions, dtype=float))
        return self._radius(p, _lengths(p[:, None, :] - self.centres))

    def _radius(self, p: np.ndarray, distance: np.ndarray) -> np.ndarray:
        """The radius at unit directions p (N, 3) from their distances (N, n) to the
        landmarks' directions."""
        return distance**3 @ self.weights + self._linear_basis(p) @ self.linear

    def radius_gradient(self, directions: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Radius (N,), m, and its gradient on the unit sphere (N, 3), m/rad."""
        p = np.atleast_2d(np.asarray(directions, dtype=float))
        offsets = p[:, None, :] - self.centres
        distance = _lengths(offsets)
        radius = self._radius(p, distance)
        gradient = np.einsum("nk,nki->ni", 3.0 * distance * self.weights, offsets)
        gradient += self.linear[1:] @ self.tangents
        gradient -= np.einsum("ni,ni->n", gradient, p)[:, None] * p
        return radius, gradient


def _lengths(offsets: np.ndarray) -> np.ndarray:
    """Lengths (N, n) of offsets (N, n, 3): ``np.linalg.norm(offsets, axis=2)`` to the bit
    (the same squares summed in the same order), without its slow reduction over three."""
    x, y, z = offsets[..., 0], offsets[..., 1], offsets[..., 2]
    return np.sqrt(x * x + y * y + z * z)
