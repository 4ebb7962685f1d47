"""Tolerance assertions for a user's test suite, and what they take.

Installing ``mbh`` registers its pytest plugin, which gives every test the fixtures
``mbh_runner`` (runs cases: ``mbh_runner.case("fourbar", "mujoco", "best", dt=1e-3)``, kept for the
session), ``mbh_reference`` and ``mbh_tolerances`` (the :class:`Tolerances` of ``tolerances.toml``
beside the test file), and the options ``--mbh-scenarios``, ``--mbh-adapters``,
``--mbh-tolerances``, ``--mbh-isolated``, ``--mbh-record`` and ``--mbh-record-margin`` (record the
tolerance file from a session's measured errors, then assert against it).  The assertions below
take the :class:`SessionCase` objects the runner returns; :class:`CaseRunner` runs cases without
pytest.  docs/formats/tolerances.md describes the tolerance file and the plugin.

Examples
--------
>>> from mbh.testing import OutputTolerance, assert_status, case_spec
>>> case_spec("fourbar", "mujoco", "best", 1e-3, t_end=0.5).case_id
'fourbar|mujoco|best|0.001|0.5'
>>> OutputTolerance(atol=2e-6)
OutputTolerance(atol=2e-06, rtol=0.0)
"""

from mbh._harness.testing.cases import (CaseRunner, SessionCase, ToleranceError, campaign_params,
                                        case_spec)
from mbh._harness.testing.tolerances import (CaseTolerance, OutputTolerance, Tolerances,
                                             assert_at_least_as_fast, assert_close_to_reference,
                                             assert_constraint_violation_below,
                                             assert_convergence_order, assert_energy_error_below,
                                             assert_status, assert_within_tolerance,
                                             constraint_violation_series, convergence_order,
                                             energy_error_series)

__all__ = ["CaseRunner", "CaseTolerance", "OutputTolerance", "SessionCase", "ToleranceError",
           "Tolerances", "assert_at_least_as_fast", "assert_close_to_reference",
           "assert_constraint_violation_below", "assert_convergence_order",
           "assert_energy_error_below", "assert_status", "assert_within_tolerance",
           "campaign_params", "case_spec", "constraint_violation_series", "convergence_order",
           "energy_error_series"]
