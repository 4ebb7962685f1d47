"""Verified references: building a scene's reference by two independent routes and
checking that they agree (``build``); the neutral branch routes through singular passages
(``routes``).  The built references are written through :mod:`mbh._harness.store.reference_files`.

May import: :mod:`mbh._harness.common`, :mod:`mbh._harness.model`, :mod:`mbh._harness.neutral`,
:mod:`mbh._harness.measure`, :mod:`mbh._harness.store` and the adapter registry (:mod:`adapters`).
"""
