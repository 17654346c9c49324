#!/usr/bin/env python
"""Runs :mod:`baselines.cli.tasks` (installed as ``soaring-tasks``)."""

import sys

from baselines.cli.tasks import main

if __name__ == "__main__":
    sys.exit(main())
