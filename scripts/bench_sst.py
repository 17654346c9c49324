#!/usr/bin/env python
"""Runs :mod:`baselines.cli.bench_sst` (installed as ``soaring-bench-sst``)."""

import sys

from baselines.cli.bench_sst import main

if __name__ == "__main__":
    sys.exit(main())
