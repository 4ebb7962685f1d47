"""What users put in their own test suites: the pytest plugin (``plugin``), the
tolerance assertions (``tolerances``), the case selection and runner behind the plugin's
fixtures (``cases``) and Hypothesis strategies that draw valid mechanisms (``strategies``).

May import: every layer below it up to :mod:`mbh._harness.run`; not :mod:`mbh._harness.report`.
"""
