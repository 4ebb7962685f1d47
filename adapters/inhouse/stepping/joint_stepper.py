"""The in-house stepper in joint coordinates (``coords=joint``) on the Python loop (the methods
the compiled loop does not run, ``loop=python``, and the compiled loop's replay of a failing
step: :mod:`~mbh._adapters.inhouse.stepping.joint_loop`): the loop of
:class:`~mbh._adapters.inhouse.stepping.driver.InhouseStepper` over (θ, θ̇) of
:class:`~mbh._adapters.inhouse.formulations.joint_coordinates.JointCoordinates`, whose
``reduce``/``expand`` map the common start to θ and every read state back to the absolute body
states the harness measures.

The one difference: an adaptive method's dense output between the steps of a correcting
treatment (``direct``) is projected onto the closure in θ (the treatment's own projection), not in
absolute coordinates, and then expanded.
"""

from __future__ import annotations

import numpy as np

from mbh._adapters.inhouse.stepping.driver import InhouseStepper


#: The run's note on its loop.
PYTHON_NOTE = "joint coordinates stepped on the Python loop (the integrator's steps in Python)"


class JointStepper(InhouseStepper):
    """One run in joint coordinates (parameters as :class:`InhouseStepper`)."""

    def __init__(self, *args, **kwargs):
        super().__init__(*args, **kwargs)
        self.notes.insert(1, PYTHON_NOTE)  # beside the model note, before the treatment's

    def _coordinates(self, t: float) -> tuple[np.ndarray, np.ndarray]:
        integrator = self.integrator
        if self.steps == 0 or not self._adaptive or t == integrator.t:
            return super()._coordinates(t)
        theta, rate = integrator.dense(t)
        if self._project_samples:
            theta, rate = self.formulation.carried(t, theta, rate)
        return self.formulation.expand(t, theta, rate)
