"""Subcommands of the ``myoface`` CLI, one module each (see :mod:`myoface.cli`).

The subcommands import the library inside the functions that run them, not at module level:
``myoface --help`` and a usage error then answer in 0.07 s, where importing the analysis alone
takes 0.85 s and the tissue model 0.7 s (measured 2026-12-01 on this project's 2-core
machine). Everything below the commands imports at module level."""

# the order in which ``myoface --help`` lists them
ORDER = [
    "demo",
    "synth",
    "analyze",
    "batch",
    "resynth",
    "encode",
    "decode",
    "export",
    "view",
    "face",
    "info",
    "bench",
]
