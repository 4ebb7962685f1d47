"""What is kept on disk: run folders of Parquet rows, trajectories and a manifest
(``runs``), their schema and its migrations (``schema``), the comparison of two stored runs
(``compare``) and the files of verified references (``reference_files``).  A report reads
these only.

May import: :mod:`mbh._harness.common`, :mod:`mbh._harness.model`.
"""
