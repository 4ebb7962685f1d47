"""The measuring stick: from the body states a run reports, the constraint violations and
errors against the reference (``metrics``), the energy balance (``energy``), the assembly branch
(``branch``) and the verdict that makes a case ``ok`` or not (``verdict``).

May import: :mod:`mbh._harness.common`, :mod:`mbh._harness.model`, :mod:`mbh._harness.neutral`.
"""
