"""Layer 6: the command-line programs (``python scripts/<name>.py`` or the console commands).

Each module has a ``main(argv=None)`` that parses the command line and returns the exit status; the
files under ``scripts/`` only call it, and ``pyproject.toml`` installs the console commands:
``soaring-evaluate``, ``soaring-reproduce-paper``, ``soaring-reference``, ``soaring-train-ppo``,
``soaring-ablation-sst``, ``soaring-bench-sst``, ``soaring-bench-env``, ``soaring-bench-model`` and
``soaring-plot-primitives``.
"""
