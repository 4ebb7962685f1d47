"""Whole jobs the command line offers on top of running and reporting: the nightly run with its
gate (``nightly``), the speed benchmark (``bench``) and the seed's comparison table
(``seedtable``).

May import: every layer below it.
"""
