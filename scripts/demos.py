#!/usr/bin/env python
"""Runs :mod:`baselines.cli.demos` (installed as ``soaring-demos``)."""

import sys

from baselines.cli.demos import main

if __name__ == "__main__":
    sys.exit(main())
