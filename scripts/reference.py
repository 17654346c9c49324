#!/usr/bin/env python
"""Runs :mod:`baselines.cli.reference` (installed as ``soaring-reference``)."""

import sys

from baselines.cli.reference import main

if __name__ == "__main__":
    sys.exit(main())
