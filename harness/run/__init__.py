"""Running cases: the campaign file and its case specifications (``spec``), one case from
build to verdict (``case``), a case specification to its stored row (``row``), the stability
sweep (``sweep``), isolated worker processes and Dask (``executor``) and a whole campaign into
the store (``campaign``).

May import: every layer below it (:mod:`mbh._harness.common` … :mod:`mbh._harness.references`) and the
adapter registry.
"""
