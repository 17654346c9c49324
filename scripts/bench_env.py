#!/usr/bin/env python
"""Runs :mod:`baselines.cli.bench_env` (installed as ``soaring-bench-env``)."""

import sys

from baselines.cli.bench_env import main

if __name__ == "__main__":
    sys.exit(main())
