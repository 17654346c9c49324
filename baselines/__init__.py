"""Baselines for soaring-env: the SST planner (``baselines.sst``) and the paper's experiment.

Note: ``baselines`` is also the import name of an old, unrelated package on PyPI; never install
both in one environment.
"""
