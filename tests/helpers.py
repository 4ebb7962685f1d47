"""Helpers shared by test files in several folders: constants and plain functions (no fixtures;
those are in ``tests/conftest.py``).  Test files import from here, never from one another."""

from __future__ import annotations

import contextlib
import io
import math
import re
import sys
import tomllib
from pathlib import Path

import numpy as np
from scipy.integrate import solve_ivp

import mbh
from mbh._harness import cli
from mbh._harness.model import scenario
from mbh._harness.model.scenario import SCENARIO_DIR
from mbh._harness.neutral.dynamics import start_accelerations

#: The tests/ folder, the repository's root above it, and the committed test data.
TESTS = Path(__file__).resolve().parent
ROOT = TESTS.parent
DATA = TESTS / "data"

GRAVITY = 9.81  # m/s², double_fourbar's gravity

#: Scenes with a shipped verified reference and the seed's outputs (crank_angle, driver "O"); the
#: adapter tests' accuracy tables are measured on them.  ``double_fourbar`` (verified along its
#: declared branch) has other outputs and is checked in tests/references/test_double_fourbar.py
#: and test_branch_route.py.
VERIFIED_SCENES = ("fourbar", "fourbar_spatial", "slider_crank", "slider_crank_planar")


def reduced_tip(times: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Tip (x, y) of ``double_fourbar``'s first crank from its one-degree-of-freedom model
    3 φ̈ = −3.5 g cos φ (derived in tests/references/test_double_fourbar.py), shape (n,) each,
    m."""
    def rhs(_t, state):
        return [state[1], -(3.5 / 3.0) * GRAVITY * np.cos(state[0])]

    solution = solve_ivp(rhs, (0.0, times[-1]), [np.pi / 2, -1.0], method="DOP853",
                         rtol=1e-13, atol=1e-13, t_eval=times)
    return np.cos(solution.y[0]), np.sin(solution.y[0])


def variant_text(name: str, replacements: list[tuple[str, str]]) -> str:
    """The shipped scenario ``name`` with each ``old`` text replaced by ``new`` (must occur)."""
    text = scenario.scenario_path(name).read_text()
    for old, new in replacements:
        assert old in text, f"fixture edit {old!r} not found in {name}.toml"
        text = text.replace(old, new)
    return text


# --- The compiled stepping path (tests/adapters/inhouse/test_compiled_path.py, test_fold.py,
# test_generated.py).

#: Bound on the difference of the compiled and the Python paths' trajectories: see the docstring of
#: tests/adapters/inhouse/test_compiled_path.py.
PATH_BOUND = 1e-10  # m and m/s (rad, rad/s on angles' velocities)

#: Scenes whose generated functions take longest to compile (~30 s a scene on a machine that has
#: not compiled them yet): their generated loops run in the slow suite.
LARGE_TRACES = ("andrews", "fourbar_spatial")


# --- Engine accelerations at the start against the neutral model
# (tests/engines/test_generated_mechanisms.py, tests/adapters/exudyn/test_exudyn_adapter.py).

#: (b) Sample spacing T (s) and number of samples of the acceleration difference, and each
#: adapter's step (s).  Exudyn steps at 2.5e-5 s: its generalized-α is 3.1e-3 off (relative) at
#: 5e-5 s on the fastest generated ladder measured (angular accelerations of 9e3 rad/s²), 6.2e-5
#: at 2.5e-5 s, while smaller steps lose digits in its index-3 Newton iteration (4.5e-3 m/s² off
#: on a slow ladder at 1e-5 s, 1.0e-4 relative on two prismatic sliders at 2e-5 s; 1.1e-5 on
#: those sliders at 2.5e-5 s).  MuJoCo steps at 1e-5 s: its soft constraints are 1.9e-3 off on
#: the fast ladder at 5e-5 s, 3.9e-4 at 1e-5 s.
ACCELERATION_SPAN = 2.5e-4
ACCELERATION_SAMPLES = 5
ACCELERATION_STEP = {"pybullet": 1e-6, "exudyn": 2.5e-5, "mujoco": 1e-5}
ACCELERATION_STEP_DEFAULT = 5e-5
#: (b) Allowed |engine − neutral| acceleration over (1 + largest neutral acceleration), per
#: adapter, measured worst over 1500 random examples / on the fastest ladders found in 4000 more
#: (9e3 rad/s², where the difference's own T⁴ error is 7.8e-5): Exudyn 1.1e-5 / 6.8e-5,
#: Pinocchio 3.8e-8 / 7.8e-5, in-house 2.9e-7 / 7.8e-5, MuJoCo 4.5e-4 / 4.5e-4 (soft equality
#: constraints, impedance 0.9999), PyBullet 5.9e-3 / 5.7e-3 (velocity-level closures); margin
#: ≥ 2.2.  (In-house starts from the harness's start like every engine; before
#: it did, 0.33 relative was measured here.)  Exudyn's bound is wider: on a generated spatial
#: mechanism of three bars hinged to ground, no gravity and accelerations of 0.03 m/s² (the
#: slow profile's example once the tests moved, which re-seeds Hypothesis), Exudyn was off by
#: 3.4e-4 relative at its 2.5e-5 s step (1.1e-4 at 1.25e-5 s, 1.0e-7 at 5e-5 s) while Pinocchio,
#: MuJoCo and the in-house formulation agreed with the neutral model to 1e-12: the error of its
#: index-3 Newton iteration, not of the model; bound 1e-3 (margin 2.9).
ACCELERATION_TOLERANCE = {"mujoco": 1e-3, "pybullet": 1.5e-2, "pinocchio": 2e-4, "exudyn": 1e-3,
                          "inhouse": 2e-4}


def measured_acceleration_gap(adapter, model, expected) -> tuple[float, float]:
    """``(|engine − neutral| acceleration, 1 + largest neutral acceleration)`` of the run of
    ``model`` with ``best``, sampled every :data:`ACCELERATION_SPAN` (m/s², rad/s²)."""
    name = adapter.name
    times = ACCELERATION_SPAN * np.arange(ACCELERATION_SAMPLES)
    step = ACCELERATION_STEP.get(name, ACCELERATION_STEP_DEFAULT)
    trajectory = adapter.simulate(model, "best", step, times[-1], times)
    assert trajectory.status == "ok", f"{name}: {trajectory.status}: {trajectory.reason}"
    measured = start_accelerations(trajectory.times, trajectory.velocity,
                                   trajectory.angular_velocity)
    worst = max(float(np.max(np.abs(measured.linear - expected.linear))),
                float(np.max(np.abs(measured.angular - expected.angular))))
    scale = 1.0 + max(float(np.max(np.abs(expected.linear))),
                      float(np.max(np.abs(expected.angular))))
    return worst, scale


# --- The ``mbh`` command (tests/report/).

#: ``mbh`` as a subprocess command line.
MBH = [sys.executable, "-m", "mbh._harness.cli"]


def run_mbh(*argv: str) -> tuple[int, str, str]:
    """``mbh ARGV`` in this process: status, stdout, stderr."""
    out, err = io.StringIO(), io.StringIO()
    with contextlib.redirect_stdout(out), contextlib.redirect_stderr(err):
        status = cli.main(list(argv))
    return status, out.getvalue(), err.getvalue()


def seed_rows() -> list[dict]:
    """A seed table in the shape of ``mbh seed-table --json`` (numbers invented for the test;
    one value as the strict-JSON string "NaN")."""
    rows = []
    for scene in ("fourbar_spatial", "slider_crank"):
        for integrator in ("rk4", "rkn4", "bdf4"):
            for stabilisation in ("none", "baumgarte", "direct"):
                rows.append({"scenario": scene, "integrator": integrator,
                             "stabilisation": stabilisation, "status": "ok", "reason": "",
                             "max_violation": 2e-3, "mean_violation": 1e-5,
                             "max_energy_error_J": "NaN" if integrator == "rk4" else 10.0,
                             "wall_time_s": 0.5, "newton_per_step": 3.0})
    return rows


#: The documentation page holding the plugin's example suite, and its section.
EXAMPLE_PAGE = ROOT / "docs" / "formats" / "tolerances.md"
EXAMPLE_SECTION = "## An example suite"


def page_files(page: Path, section: str) -> dict[str, str]:
    """The files a documentation page writes out in one of its sections (from the heading
    ``section`` to the next ``## `` heading): every fenced block whose first line is
    ``# <file path>`` (a .py or .toml file), by path."""
    text = page.read_text(encoding="utf-8")
    start = text.index(section)
    end = text.find("\n## ", start + len(section))
    files = {}
    for block in re.findall(r"```[a-z]*\n(.*?)```", text[start:end if end >= 0 else None],
                            flags=re.DOTALL):
        found = re.match(r"# (\S+\.(?:py|toml))\b", block)
        if found:
            files[found.group(1)] = block
    return files


def example_suite_files() -> dict[str, str]:
    """The example files of the documentation's example suite (:func:`page_files`)."""
    return page_files(EXAMPLE_PAGE, EXAMPLE_SECTION)


def planar_scene_in_space(scene: str, name: str, driver: str, duration: float = 1.0):
    """Shipped planar scene ``scene`` drawn in space with a revolute about z at every joint
    (its bodies and joint locations as in its file, its ``driver`` joint driven from rest)."""
    document = tomllib.loads((SCENARIO_DIR / f"{scene}.toml").read_text(encoding="utf-8"))
    builder = mbh.MechanismBuilder(name, kind="spatial", duration=duration,
                                   gravity=document["gravity"])
    for body in document["bodies"]:
        half = math.radians(body["angle_deg"]) / 2.0
        builder = builder.body(body["name"], mass=body["mass"], inertia=body["inertia"],
                               position=body["position"],
                               quaternion=[math.cos(half), 0.0, 0.0, math.sin(half)])
    for joint in document["joints"]:
        builder = builder.joint(joint["name"], "revolute", body1=joint["body1"],
                                body2=joint["body2"], location=joint["location"],
                                axis=[0.0, 0.0, 1.0])
    return (builder.initial(driver=driver, value=0.0, rate=0.0)
            .output("crank_angle", "joint_angle", joint=driver).build())


def parallel_revolute_fourbar():
    """The seed four-bar's file drawn in space with four revolutes about z: three redundant
    equations (the two tilts of two joints)."""
    return planar_scene_in_space("fourbar", "fourbar_4r", "O")


def bennett_linkage(crank_angle: float = 0.8, a: float = 1.0, b: float = 1.5,
                    twist_deg: float = 30.0):
    """Bennett's spatial 4R linkage (Bennett 1903; the overconstrained loop of mechanism
    textbooks), typed from its description: four links of lengths a, b, a, b (m) with twists α,
    β, α, β between neighbouring joint axes, a / sin α = b / sin β, no offsets; opposite joint
    angles are opposite (θ₃ = −θ₁, θ₄ = −θ₂) and tan(θ₁/2) tan(θ₂/2) = sin((β + α)/2) /
    sin((β − α)/2).  The fourth link is the ground, the other three 1 kg bodies at their links'
    midpoints; gravity along −z; the first joint driven at 1 rad/s.  3 moving bodies, 4
    revolutes: 3 redundant equations (Grübler's count gives −2, the mobility is 1)."""
    alpha = math.radians(twist_deg)
    beta = math.asin(b * math.sin(alpha) / a)
    theta2 = 2.0 * math.atan(math.sin((beta + alpha) / 2.0) / math.sin((beta - alpha) / 2.0)
                             / math.tan(crank_angle / 2.0))

    def turned(axis, angle, vector):  # Rodrigues' rotation of ``vector`` about unit ``axis``
        return (vector * math.cos(angle) + np.cross(axis, vector) * math.sin(angle)
                + axis * (axis @ vector) * (1.0 - math.cos(angle)))

    point, axis, normal = np.zeros(3), np.array([0.0, 0.0, 1.0]), np.array([1.0, 0.0, 0.0])
    points, axes = [], []
    for k, angle in enumerate((crank_angle, theta2, -crank_angle, -theta2)):
        points.append(point)
        axes.append(axis)
        normal = turned(axis, angle, normal)
        point = point + (a if k % 2 == 0 else b) * normal
        axis = turned(normal, alpha if k % 2 == 0 else beta, axis)
    assert np.abs(point).max() < 1e-12 and np.abs(axis - axes[0]).max() < 1e-12  # closed
    links = ("ground", "link1", "link2", "link3")
    builder = mbh.MechanismBuilder("bennett", kind="spatial", duration=1.0,
                                   gravity=[0.0, 0.0, -9.81])
    for k in (1, 2, 3):
        builder = builder.body(links[k], mass=1.0, inertia=[0.05, 0.05, 0.05],
                               position=((points[k - 1] + points[k]) / 2.0).tolist(),
                               quaternion=[1.0, 0.0, 0.0, 0.0])
    for k in range(4):  # joint k between link k (ground for k = 0) and link k + 1 (mod 4)
        builder = builder.joint(f"J{k + 1}", "revolute", body1=links[k],
                                body2=links[(k + 1) % 4], location=points[k].tolist(),
                                axis=axes[k].tolist())
    return (builder.initial(driver="J1", value=0.0, rate=1.0)
            .output("crank_angle", "joint_angle", joint="J1").build())


def spring_damper_tree():
    """A planar tree drawn by hand: a pendulum of two links from ground with a third link on the
    first link's middle, a spring-damper from the second link's tip to ground and another
    between the two branches; starts at rest with exact zeros (links along the axes)."""
    builder = mbh.MechanismBuilder("spring_tree", kind="planar", plane="xy", duration=1.0,
                                   gravity=[0.0, -9.81, 0.0])
    for name, position, angle in (("upper", [0.5, 0.0, 0.0], 0.0),
                                  ("lower", [1.0, -0.4, 0.0], -90.0),
                                  ("side", [0.25, 0.3, 0.0], 90.0)):
        builder = builder.body(name, mass=2.0, inertia=[0.01, 0.2, 0.2], position=position,
                               angle_deg=angle)
    builder = (builder.joint("O", "revolute", body1="ground", body2="upper", location=[0, 0, 0])
               .joint("E", "revolute", body1="upper", body2="lower", location=[1.0, 0.0, 0.0])
               .joint("M", "revolute", body1="upper", body2="side", location=[0.25, 0.0, 0.0])
               .force("spring_damper", name="tip", body1="ground", body2="lower",
                      location1=[1.5, -1.0, 0.0], location2=[1.0, -0.8, 0.0], stiffness=400.0,
                      damping=2.0, free_length=0.3)
               .force("spring_damper", name="between", body1="side", body2="lower",
                      location1=[0.25, 0.6, 0.0], location2=[1.0, -0.8, 0.0], stiffness=50.0,
                      damping=0.5, free_length=1.5))
    return (builder.initial(driver="O", value=0.0, rate=0.0)
            .output("upper_angle", "joint_angle", joint="O").build())


def flat_parallelogram(duration: float = 0.4):
    """The shipped parallelogram four-bar's rods (principal moment 0 about their length: flat
    bodies) drawn in space with four revolutes about z: three redundant equations.  Over 0.4 s,
    before its flattened passage at 0.54 s."""
    return planar_scene_in_space("parallelogram_fourbar", "flat_parallelogram", "O1", duration)


def rsrr_fourbar():
    """``fourbar_spatial`` with its cylindrical joint made a revolute: R-S-R-R, one redundant
    equation (the spherical joint's spin about the coupler's length)."""
    document = tomllib.loads(variant_text("fourbar_spatial", [('type = "cylindrical"',
                                                               'type = "revolute"')]))
    return scenario.from_document(document, "fourbar_rsrr", "fourbar_rsrr")


def ball_pendulum():
    """A hinged arm carrying a bob on a ball joint, drawn by hand: an open chain whose spanning
    tree must hold the ball (no joint coordinates for it here); it declares no output."""
    return (mbh.MechanismBuilder("ball_pendulum", kind="spatial", duration=1.0,
                                 gravity=[0.0, 0.0, -9.81])
            .body("arm", mass=1.0, inertia=[0.01, 0.1, 0.1], position=[0.5, 0.0, 0.0])
            .body("bob", mass=1.0, inertia=[0.01, 0.01, 0.01], position=[1.5, 0.0, 0.0])
            .joint("hinge", "revolute", body1="ground", body2="arm", location=[0, 0, 0],
                   axis=[0.0, 1.0, 0.0])
            .joint("ball", "spherical", body1="arm", body2="bob", location=[1.0, 0.0, 0.0])
            .initial(driver="hinge", value=0.0, rate=0.0).build())
