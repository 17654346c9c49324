#!/usr/bin/env python
"""Runs :mod:`baselines.cli.train_ppo` (installed as ``soaring-train-ppo``)."""

import sys

from baselines.cli.train_ppo import main

if __name__ == "__main__":
    sys.exit(main())
