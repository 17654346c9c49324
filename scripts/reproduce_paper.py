#!/usr/bin/env python
"""Runs :mod:`baselines.cli.reproduce_paper` (installed as ``soaring-reproduce-paper``)."""

import sys

from baselines.cli.reproduce_paper import main

if __name__ == "__main__":
    sys.exit(main())
