"""Tolerance assertions for a user's pytest suite, and the plugin's fixtures.

Installing ``mbh`` registers its pytest plugin (fixtures ``mbh_runner``, ``mbh_reference``,
``mbh_tolerances``; options ``--mbh-scenarios``, ``--mbh-adapters``, ``--mbh-tolerances``,
``--mbh-isolated``).  The assertions below take the cases ``mbh_runner`` returns;
docs/formats/tolerances.md describes the tolerance file and the plugin.

Examples
--------
>>> from mbh.testing import assert_status, convergence_order
>>> callable(assert_status) and callable(convergence_order)
True
"""

from mbh._harness.testing.cases import Selection, SessionCase, ToleranceError, case_spec
from mbh._harness.testing.plugin import campaign_params
from mbh._harness.testing.tolerances import (CaseTolerance, OutputTolerance, Tolerances,
                                             assert_at_least_as_fast, assert_close_to_reference,
                                             assert_constraint_violation_below,
                                             assert_convergence_order, assert_energy_error_below,
                                             assert_status, assert_within_tolerance,
                                             constraint_violation_series, convergence_order,
                                             energy_error_series)

__all__ = ["CaseTolerance", "OutputTolerance", "Selection", "SessionCase", "ToleranceError",
           "Tolerances", "assert_at_least_as_fast", "assert_close_to_reference",
           "assert_constraint_violation_below", "assert_convergence_order",
           "assert_energy_error_below", "assert_status", "assert_within_tolerance",
           "campaign_params", "case_spec", "constraint_violation_series", "convergence_order",
           "energy_error_series"]
