"""Verified references: building a scene's reference by two independent routes and
checking that they agree (``build``); the neutral branch routes through singular passages
(``routes``).  The built references are written through :mod:`harness.store.reference_files`.

May import: :mod:`harness.common`, :mod:`harness.model`, :mod:`harness.neutral`,
:mod:`harness.measure`, :mod:`harness.store` and the adapter registry (:mod:`adapters`).
"""
