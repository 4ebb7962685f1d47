"""Closed-form kinematic invariants along the engines' runs, from published descriptions.

Each mechanism's joints tie its angles by a relation known in closed form; every engine's run
the harness marks ``ok`` must keep it.  The angles and positions are read from the body states
(:mod:`tests.outside.independent`), the link lengths and twists typed from the mechanism's
description, never taken from the harness's reference or outputs.

* Bennett's 4R linkage (Bennett 1903, "A new mechanism", Engineering 76, 777–778; the
  half-angle form as written e.g. by Chen & You 2005, Proc. R. Soc. A 461, "Mobile assemblies
  based on the Bennett linkage"): links of lengths a, b, a, b with twists α, β, α, β and
  a / sin α = b / sin β have θ₁ + θ₃ = θ₂ + θ₄ = 0 (mod 2π) and
  tan(θ₁/2) tan(θ₂/2) = sin((β + α)/2) / sin((β − α)/2).  θₖ is the Denavit–Hartenberg joint
  angle: the right-handed turn about joint k's axis from the common normal of the link before
  it to that of the link after it (each link's normal runs from its first joint to its second);
  α is the twist of the link of length a that follows joint 1.  Statements of the relation
  differ in sign conventions, so the one used is checked, not trusted: the drawing of
  :func:`tests.helpers.bennett_linkage` closes with it (the helper asserts the loop closes to
  1e-12 m), and the engines' runs keep it along a motion.  The relation is checked as the
  bounded residual sin(θ₁/2) sin(θ₂/2) sin((β − α)/2) − cos(θ₁/2) cos(θ₂/2) sin((β + α)/2).
* Freudenstein's equation of the planar four-bar (Freudenstein 1955, "Approximate synthesis of
  four-bar linkages", Trans. ASME 77, 853–861): with crank a, coupler b, rocker c and frame d,
  K₁ cos φ − K₂ cos ψ + K₃ = cos(φ − ψ), K₁ = d/c, K₂ = d/a, K₃ = (a² − b² + c² + d²)/(2ac).
  Written out from |C − B|² = b² (B = a(cos φ, sin φ), C = (d + c cos ψ, c sin ψ) with the angles
  from the frame line directed crank pivot → rocker pivot) the closure reads
  (d/a) cos ψ − (d/c) cos φ + K₃ = cos(φ − ψ), the form of Norton's Design of Machinery
  (K₁ cos θ₄ − K₂ cos θ₂ + K₃ = cos(θ₂ − θ₄), K₁ = d/a, K₂ = d/c); the form above, with
  K₁ = d/c and K₂ = d/a, holds for both angles measured from the opposite direction (φ + π,
  ψ + π), which is how the test writes it (the signs of the cosine terms depend on the direction
  the angles are measured from, which statements of the equation differ on).  Rouvinen's
  four-bar (``fourbar``): a = 2, b = 4, c = 4, d = 2.5 m (Rouvinen 2003, §6.1, as fixed in the
  scene's notes).
* The slider-crank's exact slider position (e.g. Uicker, Pennock & Shigley, Theory of Machines
  and Mechanisms, the offset slider-crank's loop equation): a crank r from O at angle θ, a rod l
  to a slider on the line y = e, x = r cos θ + √(l² − (r sin θ − e)²).  ``slider_crank_planar``:
  r = 0.5, l = 1.8, e = 0 m.  The spatial ``slider_crank`` (Rouvinen 2003, §6.2) turns its crank
  about x in the plane x = 0, θ from −z towards +y, and slides along x on the line y = 0,
  z = −e with e = 0.5 m: from |S − A| = l, x = √(l² − r² sin² θ − (r cos θ − e)²).

Measured on 2026-11-29 (largest deviation over the run, the dimensionless residual or m; the
bound is the measured value times :data:`MARGIN`, and never below :data:`FLOOR`: a deviation at
round-off differs between CPUs).  Each invariant is a consequence of the joints alone, so an
engine that keeps its joints to round-off keeps it to round-off: these tests check that each
engine's joints are the described mechanism's (axes, points, lengths), not its dynamics.
"""

from __future__ import annotations

import math

import numpy as np
import pytest

import mbh
from tests.helpers import bennett_linkage
from tests.outside.independent import (body_points, body_vectors, engine_cases, ok_run,
                                       planar_angle, signed_angle)

#: A deviation's bound is this multiple of the measured one (engines' errors above round-off
#: are integration errors, the same on any CPU up to round-off)...
MARGIN = 3.0
#: ... and never below this (dimensionless residuals of O(1) terms, and m on 1 m links): 10× the
#: largest projection tolerance of an engine that projects (Pinocchio's 1e-12), below which a
#: run may land anywhere on another CPU; the in-house and Exudyn runs keep their joints to
#: ~1e-15, and any error of a joint's geometry shows at ≥ 1e-4.
FLOOR = 1e-11

# --- Bennett's linkage: the helper's drawing, typed here from its description.
BENNETT_A, BENNETT_B, BENNETT_TWIST_DEG, BENNETT_START = 1.0, 1.5, 30.0, 0.8
BENNETT_DT, BENNETT_T_END = 1e-3, 1.0
#: Largest Bennett residual (relation; θ₁ + θ₃; θ₂ + θ₄ in rad) per engine, measured at dt = 1e-3
#: s over 1 s (θ₁ turns through 1.0 rad, θ₂ through ±π).
BENNETT_MEASURED = {"inhouse": (1.4e-16, 1.3e-15, 1.3e-15), "mujoco": (2.9e-10, 1.7e-9, 2.7e-9),
                    "pinocchio": (8.5e-16, 6.9e-15, 3.3e-14)}
BENNETT_NOT_OK = {
    "exudyn": "failed: engine limit: Exudyn's Newton iteration on redundant equations (23 "
              "algebraic equations on 21 coordinates: at least 3 redundant …): exudyn solver "
              "failed: reduction of step size reached minimum step size … (overconstrained loop: "
              "3 of the 20 joint equations are redundant)",
    "pybullet": "unsupported: cut joint 'J2' is revolute: a Bullet multibody closes loops only "
                "with point-to-point constraints",
}


def bound(measured: float) -> float:
    """The test's bound on a deviation measured at ``measured``."""
    return max(MARGIN * measured, FLOOR)


@pytest.fixture(scope="module")
def bennett() -> mbh.Mechanism:
    return bennett_linkage(crank_angle=BENNETT_START, a=BENNETT_A, b=BENNETT_B,
                           twist_deg=BENNETT_TWIST_DEG)


def bennett_angles(mech: mbh.Mechanism, trajectory) -> np.ndarray:
    """The four Denavit–Hartenberg joint angles θ₁..θ₄ at every sample, rad, shape (n, 4).

    Each link's normal is the unit vector from its first joint's point to its second's, both
    points carried by that link's body state (the ground's are fixed); a joint's axis is the one
    carried by the link after it."""
    links = ["ground", *(body.name for body in mech.bodies)]
    joints = mech.joints  # joints[k] = J(k + 1), from links[k] to links[k + 1] (mod 4)
    assert [(j.body1, j.body2) for j in joints] == list(zip(links, links[1:] + links[:1]))

    def carried(link: str, vector: np.ndarray, point: bool) -> np.ndarray:
        if link == "ground":
            return np.broadcast_to(vector, (trajectory.n_samples, 3))
        move = body_points if point else body_vectors
        return move(trajectory, mech.body_index(link), vector)

    normals = []
    for k, link in enumerate(links):  # links[k] runs from joints[k − 1] to joints[k]
        start = carried(link, joints[k - 1].point2, True)
        end = carried(link, joints[k].point1, True)
        normals.append((end - start) / np.linalg.norm(end - start, axis=1, keepdims=True))
    return np.stack([signed_angle(normals[k], normals[(k + 1) % 4],
                                  carried(links[(k + 1) % 4], joints[k].axis2, False))
                     for k in range(4)], axis=1)


def bennett_residuals(angles: np.ndarray) -> np.ndarray:
    """Largest |relation residual|, |θ₁ + θ₃| and |θ₂ + θ₄| (wrapped to (−π, π]) over the run."""
    alpha = math.radians(BENNETT_TWIST_DEG)
    beta = math.asin(BENNETT_B * math.sin(alpha) / BENNETT_A)
    half = angles / 2.0
    relation = (np.sin(half[:, 0]) * np.sin(half[:, 1]) * math.sin((beta - alpha) / 2.0)
                - np.cos(half[:, 0]) * np.cos(half[:, 1]) * math.sin((beta + alpha) / 2.0))
    opposite = np.angle(np.exp(1j * (angles[:, :2] + angles[:, 2:])))
    return np.array([np.abs(relation).max(), *np.abs(opposite).max(axis=0)])


@pytest.mark.parametrize("engine", engine_cases(BENNETT_NOT_OK))
def test_bennett_linkage_keeps_its_input_output_relation(bennett, engine):
    """Bennett (1903); Chen & You (2005), eq. 2.2–2.3: see the module docstring."""
    angles = bennett_angles(bennett, ok_run(bennett, engine, BENNETT_DT, BENNETT_T_END))
    assert np.ptp(angles[:, 0]) > 0.5  # the crank turns: the relation is tested along a motion
    found = bennett_residuals(angles)
    allowed = [bound(value) for value in BENNETT_MEASURED[engine]]
    assert (found <= allowed).all(), f"{engine}: {found} > {allowed}"


# --- Freudenstein's equation on Rouvinen's four-bar (driven by its −1200 N·m torque).
CRANK, COUPLER, ROCKER, FRAME = 2.0, 4.0, 4.0, 2.5
FOURBAR_DT, FOURBAR_T_END = 1e-3, 4.0
#: Largest |Freudenstein residual| over the 4 s run at dt = 1e-3 s (the crank turns 13.4 rad),
#: per engine.
FREUDENSTEIN_MEASURED = {"inhouse": 2.3e-15, "mujoco": 1.6e-6, "pinocchio": 6.3e-13,
                         "exudyn": 2.2e-15, "pybullet": 1.05e-4}


def freudenstein_residual(crank_angle: np.ndarray, rocker_angle: np.ndarray) -> np.ndarray:
    """K₁ cos φ − K₂ cos ψ + K₃ − cos(φ − ψ), the angles (rad) of crank and rocker measured from
    the frame line directed crank pivot → rocker pivot (turned by π for Freudenstein's form)."""
    phi, psi = crank_angle + np.pi, rocker_angle + np.pi
    k1, k2 = FRAME / ROCKER, FRAME / CRANK
    k3 = (CRANK ** 2 - COUPLER ** 2 + ROCKER ** 2 + FRAME ** 2) / (2.0 * CRANK * ROCKER)
    return k1 * np.cos(phi) - k2 * np.cos(psi) + k3 - np.cos(phi - psi)


@pytest.mark.parametrize("engine", engine_cases({}))
def test_fourbar_keeps_freudensteins_equation(engine):
    """Freudenstein (1955) on Rouvinen's four-bar: see the module docstring.  The crank and the
    rocker carry their links along their body x axes (the scene's notes), and the frame line
    O → R is the world's x axis."""
    mech = mbh.load_scenario("fourbar")
    trajectory = ok_run(mech, engine, FOURBAR_DT, FOURBAR_T_END)
    crank = planar_angle(trajectory, mech.body_index("crank"))
    rocker = planar_angle(trajectory, mech.body_index("rocker"))
    assert np.ptp(crank) > 1.0
    found = np.abs(freudenstein_residual(crank, rocker)).max()
    assert found <= bound(FREUDENSTEIN_MEASURED[engine]), engine


# --- The slider-crank's exact slider position.
RADIUS, ROD = 0.5, 1.8
SLIDER_DT, SLIDER_T_END = 1e-3, 4.0
#: Largest |x − closed form| over the 4 s run at dt = 1e-3 s, m, per scene and engine.
SLIDER_MEASURED = {
    "slider_crank_planar": {"inhouse": 8.9e-15, "mujoco": 1.4e-5, "pinocchio": 1.2e-12,
                            "exudyn": 1.1e-14},
    "slider_crank": {"inhouse": 8.9e-16, "mujoco": 4.4e-7, "pinocchio": 7.6e-13,
                     "exudyn": 3.0e-13},
}
#: PyBullet leaves both slider-cranks' motion within the 4 s (the harness's turn bound).
SLIDER_NOT_OK = {
    "slider_crank_planar": {"pybullet": "failed at t = 2.91 s: left the reference's motion "
                                        "(crank turned 0.1011 rad from it; bound 0.1 rad)"},
    "slider_crank": {"pybullet": "failed at t = 1.62 s: left the reference's motion (crank "
                                 "turned 0.1031 rad from it; bound 0.1 rad)"},
}


def slider_deviation(scene: str, trajectory, mech: mbh.Mechanism) -> np.ndarray:
    """The slider's x (m) less its closed form in the crank angle, at every sample."""
    crank = mech.body_index("crank")
    slider_x = trajectory.position[:, mech.body_index("slider"), 0]
    if scene == "slider_crank_planar":
        theta, offset = planar_angle(trajectory, crank), 0.0
        return slider_x - (RADIUS * np.cos(theta)
                           + np.sqrt(ROD ** 2 - (RADIUS * np.sin(theta) - offset) ** 2))
    # Spatial: the crank's body x axis points from O to A (along −z at the start).
    along = body_vectors(trajectory, crank, [1.0, 0.0, 0.0])
    n = trajectory.n_samples
    theta = signed_angle(np.tile([0.0, 0.0, -1.0], (n, 1)), along, np.tile([1.0, 0.0, 0.0], (n, 1)))
    offset = 0.5
    return slider_x - np.sqrt(ROD ** 2 - (RADIUS * np.sin(theta)) ** 2
                              - (RADIUS * np.cos(theta) - offset) ** 2)


@pytest.mark.parametrize("scene, engine", [case for scene in sorted(SLIDER_MEASURED)
                                           for case in engine_cases(SLIDER_NOT_OK[scene], scene)])
def test_slider_crank_slider_is_where_the_closed_form_puts_it(scene, engine):
    """The slider-crank's loop equation (module docstring), planar and spatial."""
    mech = mbh.load_scenario(scene)
    trajectory = ok_run(mech, engine, SLIDER_DT, SLIDER_T_END)
    found = np.abs(slider_deviation(scene, trajectory, mech)).max()
    assert found <= bound(SLIDER_MEASURED[scene][engine]), engine
