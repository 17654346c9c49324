#!/usr/bin/env python
"""Runs :mod:`baselines.cli.probe_lookahead` (installed as ``soaring-probe-lookahead``)."""

import sys

from baselines.cli.probe_lookahead import main

if __name__ == "__main__":
    sys.exit(main())
