"""Designs: :func:`~tolsynth.synthesize` (one or more poses), the whole workspace, process
choice, Pareto fronts, budgets, sweeps and the paper's reproduction."""
