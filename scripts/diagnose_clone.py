#!/usr/bin/env python
"""Runs :mod:`baselines.cli.diagnose_clone` (installed as ``soaring-diagnose-clone``)."""

import sys

from baselines.cli.diagnose_clone import main

if __name__ == "__main__":
    sys.exit(main())
