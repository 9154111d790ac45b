"""One module per `propid` sub-command.

Each module defines ``NAME`` (the sub-command), ``HELP`` (one line),
``add_arguments(parser)`` and ``run(args) -> int`` (the exit code).
"""

# The order here is the order shown by `propid --help`.
COMMAND_MODULES = [
    "listen",
    "log",
    "plot",
    "table1",
    "convert",
    "replay",
    "campaign",
    "gap",
    "gap_bench",
    "observability",
    "damage_bench",
    "table1_extended",
    "bound_check",
    "effects_demo",
    "real_data",
]
