"""Subcommands of the ``myoface`` CLI, one module each (see :mod:`myoface.cli`)."""

# the order in which ``myoface --help`` lists them
ORDER = ["demo", "synth", "analyze", "batch", "resynth", "view", "face", "info", "bench"]
