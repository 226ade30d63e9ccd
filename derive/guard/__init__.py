"""Guards of ``python -m derive``: refuse a runaway input before the symbolic work, and keep that work stoppable.

:mod:`~derive.guard.cost` estimates a derivation's time and memory from the chain alone (power laws
calibrated on :mod:`~derive.guard.synthetic` chains) and :mod:`~derive.guard.guard` pre-scans a model
file without SymPy, logs each stage and runs the symbolic work in an interruptible child process.
Light imports only (no SymPy, no CasADi), so the guard runs before the heavy imports.
"""
