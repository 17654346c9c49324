#!/usr/bin/env python
"""Runs :mod:`baselines.cli.plot_primitives` (installed as ``soaring-plot-primitives``)."""

import sys

from baselines.cli.plot_primitives import main

if __name__ == "__main__":
    sys.exit(main())
