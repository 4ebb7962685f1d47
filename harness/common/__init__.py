"""Small utilities every layer may use: the project's error base class, strict JSON output,
number formatting for messages and tables, the progress bar, captured engine output and the
record of where a run ran (git state, package versions, machine).

Owns no physics.  Imports nothing from ``harness`` or ``adapters``.
"""
