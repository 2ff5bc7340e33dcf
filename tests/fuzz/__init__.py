"""Mutation fuzzing of ``colossus import`` and ``colossus validate`` (issue 12).

Run from the repository root::

    python -m tests.fuzz -n 300                     # what CI runs (tests/cli/test_fuzz.py), ~1-2 min
    python -m tests.fuzz -n 10000 --out fuzz-cases  # a long campaign (make fuzz N=10000)
    python -m tests.fuzz --replay fuzz-cases/000123-internal-error  # one saved case again

Modules: :mod:`.seeds` (the seed files: ``samples/`` and ``../shared/corpus/``, read in place),
:mod:`.mutators` (structure-aware per format, and byte-level), :mod:`.oracle` (one case run
in-process through click's ``CliRunner`` or as a real subprocess, and judged),
:mod:`.campaign` (worker processes with an address-space cap and a per-case timeout, the
summary, the saved bad cases).
"""
