#!/usr/bin/env python
"""Runs :mod:`baselines.cli.ablation_sst` (installed as ``soaring-ablation-sst``)."""

import sys

from baselines.cli.ablation_sst import main

if __name__ == "__main__":
    sys.exit(main())
