#!/usr/bin/env python
"""Runs :mod:`baselines.cli.bench_model` (installed as ``soaring-bench-model``)."""

import sys

from baselines.cli.bench_model import main

if __name__ == "__main__":
    sys.exit(main())
