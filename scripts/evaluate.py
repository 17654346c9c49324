#!/usr/bin/env python
"""Runs :mod:`baselines.cli.evaluate` (installed as ``soaring-evaluate``)."""

import sys

from baselines.cli.evaluate import main

if __name__ == "__main__":
    sys.exit(main())
