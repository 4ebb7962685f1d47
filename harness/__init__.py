"""The engine-neutral core of ``mbh``, one subpackage per step of the data flow, bottom first:

``common``      errors, JSON and number formatting, progress, captured output, run environment
``model``       scenario files and families → the validated, hashed mechanism; trajectories
``neutral``     the harness's own joint equations, assembly, rank, conditioning and the common start
``measure``     the measuring stick: errors, joint gaps, energy, branch, and the verdict
``store``       run folders (Parquet rows, trajectories, manifest) and the reference files
``references``  building verified references by two independent routes
``run``         campaign files, one case, a case's row, executors, sweeps, whole campaigns
``report``      HTML and PDF reports, read from the store only
``testing``     the pytest plugin, tolerance assertions and Hypothesis strategies
``jobs``        nightly, bench and the seed table
``cli``         the ``mbh`` command

A layer imports only layers below it (``tests/test_layers.py``; docs/design.md, "Layers").  The
adapters (``adapters/``) sit between ``measure`` and ``references``, reached only through their
registry.
"""
