"""Mass properties of a rigid body made of simple parts: point masses, slender rods, boxes, solid
cylinders and solid spheres, each homogeneous, combined by the parallel-axis theorem.

Every part is placed in one frame (a scenario places parts in world coordinates at the start,
like its joints: docs/formats/scenario.md); centres are in m, masses in kg, inertias in kg·m²
about the stated centre in that frame's axes.

Part inertias about the part's own centre (m its mass; 1 the 3 × 3 identity; a a unit axis)
--------------------------------------------------------------------------------------------
* point mass: I = 0.
* slender rod of length L along a (no thickness, so no moment about its own axis):
  I = m L²/12 (1 − a aᵀ).
* box with edges (s_x, s_y, s_z) along the columns of its rotation R:
  I = R diag(s_y² + s_z², s_x² + s_z², s_x² + s_y²) Rᵀ · m/12.
* solid cylinder of radius r and length L along a:
  I = m r²/2 · a aᵀ + m (3r² + L²)/12 · (1 − a aᵀ).
* solid sphere of radius r: I = 2/5 m r² · 1.

A part given by density has the mass density × measure, the measure being the rod's length
(density in kg/m, per length) or the solid's volume (density in kg/m³): box s_x s_y s_z,
cylinder π r² L, sphere 4/3 π r³.

Combination (the parallel-axis, or Huygens–Steiner, theorem)
------------------------------------------------------------
M = Σ mᵢ,  c = Σ mᵢ cᵢ / M,  I = Σ [Iᵢ + mᵢ (|dᵢ|² 1 − dᵢ dᵢᵀ)] with dᵢ = cᵢ − c.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Sequence

import numpy as np


@dataclass(frozen=True)
class MassProperties:
    """Mass, centre of mass and inertia of a part or of a body made of parts.

    Attributes
    ----------
    mass : float
        kg.
    centre : ndarray, shape (3,)
        Centre of mass, m.
    inertia : ndarray, shape (3, 3)
        Inertia tensor about ``centre``, kg·m², in the axes the centre is given in.
    """

    mass: float
    centre: np.ndarray
    inertia: np.ndarray


def _along(axis: np.ndarray) -> np.ndarray:
    """a aᵀ for the unit vector along ``axis`` (3,): the projector onto the axis."""
    unit = np.asarray(axis, dtype=float) / np.linalg.norm(axis)
    return np.outer(unit, unit)


def point(mass: float, centre: np.ndarray) -> MassProperties:
    """A point mass (kg) at ``centre`` (m, shape (3,)): no inertia about itself."""
    return MassProperties(mass, np.asarray(centre, dtype=float), np.zeros((3, 3)))


def rod(mass: float, length: float, centre: np.ndarray, axis: np.ndarray) -> MassProperties:
    """A slender rod of ``length`` (m) along ``axis`` (shape (3,), any length) with its middle at
    ``centre`` (m): m L²/12 about every line through the middle perpendicular to the axis, none
    about the axis."""
    return MassProperties(mass, np.asarray(centre, dtype=float),
                          mass * length ** 2 / 12.0 * (np.eye(3) - _along(axis)))


def box(mass: float, size: np.ndarray, centre: np.ndarray, rotation: np.ndarray) -> MassProperties:
    """A solid box with edge lengths ``size`` (m, shape (3,)) along the columns of ``rotation``
    (shape (3, 3), the box's axes in the placement frame), centred at ``centre`` (m)."""
    sx, sy, sz = np.asarray(size, dtype=float) ** 2
    own = mass / 12.0 * np.diag([sy + sz, sx + sz, sx + sy])
    return MassProperties(mass, np.asarray(centre, dtype=float), rotation @ own @ rotation.T)


def cylinder(mass: float, radius: float, length: float, centre: np.ndarray,
             axis: np.ndarray) -> MassProperties:
    """A solid circular cylinder of ``radius`` and ``length`` (m) along ``axis`` (shape (3,)),
    centred at ``centre`` (m): m r²/2 about its axis, m (3r² + L²)/12 across it."""
    along = _along(axis)
    inertia = (mass * radius ** 2 / 2.0 * along
               + mass * (3.0 * radius ** 2 + length ** 2) / 12.0 * (np.eye(3) - along))
    return MassProperties(mass, np.asarray(centre, dtype=float), inertia)


def sphere(mass: float, radius: float, centre: np.ndarray) -> MassProperties:
    """A solid sphere of ``radius`` (m) centred at ``centre`` (m): 2/5 m r² about every axis."""
    return MassProperties(mass, np.asarray(centre, dtype=float),
                          0.4 * mass * radius ** 2 * np.eye(3))


def box_volume(size: np.ndarray) -> float:
    """Volume of a box with edge lengths ``size`` (m, shape (3,)), m³."""
    return float(np.prod(size))


def cylinder_volume(radius: float, length: float) -> float:
    """Volume of a solid cylinder, π r² L, m³."""
    return math.pi * radius ** 2 * length


def sphere_volume(radius: float) -> float:
    """Volume of a solid sphere, 4/3 π r³, m³."""
    return 4.0 / 3.0 * math.pi * radius ** 3


def shifted(inertia: np.ndarray, mass: float, offset: np.ndarray) -> np.ndarray:
    """Inertia (kg·m², (3, 3)) about a point ``offset`` (m, (3,)) away from the centre of mass
    of a part of ``mass`` (kg) whose centroidal inertia is ``inertia``: the parallel-axis
    theorem, I + m (|d|² 1 − d dᵀ)."""
    d = np.asarray(offset, dtype=float)
    return inertia + mass * (float(d @ d) * np.eye(3) - np.outer(d, d))


def combined(parts: Sequence[MassProperties]) -> MassProperties:
    """The rigid union of ``parts`` (at least one): total mass, common centre of mass and the
    inertia about it (module docstring)."""
    mass = sum(part.mass for part in parts)
    centre = sum(part.mass * part.centre for part in parts) / mass
    inertia = sum(shifted(part.inertia, part.mass, part.centre - centre) for part in parts)
    return MassProperties(mass, centre, inertia)
