"""The ``mbh`` commands, one module per group (the layout of asv's ``asv/commands``).

Each module defines its commands' subparsers and the functions that run them
(``add_commands(subparsers)``; every parser's ``func`` takes the parsed arguments and returns
the exit status).  :mod:`.options` holds the options several commands share, :mod:`.output` the
printing, :mod:`.exits` what each exit status means; :mod:`mbh._harness.cli` builds the parser
from the modules and turns the project's errors into one message and an exit status.
"""
