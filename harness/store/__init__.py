"""What is kept on disk: run folders of Parquet rows, trajectories and a manifest (``runs``,
made of the results root ``location``, the ``manifest`` and the listing of runs, the Parquet
``rows``, the ``trajectory_files``, the ``writer_lock``, atomic ``files`` and the ``problems``
of damaged files), the ``cache`` of identical cases, the schema and its migrations
(``schema``), the comparison of two stored runs (``compare``) and the files of verified
references (``reference_files``).  A report reads these only.

May import: :mod:`mbh._harness.common`, :mod:`mbh._harness.model`.
"""
