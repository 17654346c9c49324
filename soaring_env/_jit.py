"""Compilation flags shared by every numba kernel."""

#: LLVM fast-math flags: contraction (FMA), reciprocal and reassociation only. Never ``nnan`` /
#: ``ninf``: the kernels test for NaN (e.g. "no previous airspeed") and must keep IEEE semantics there.
FASTMATH = {"contract", "arcp", "reassoc"}
