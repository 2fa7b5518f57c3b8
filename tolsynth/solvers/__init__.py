"""Solvers of the tolerance problem, all reading the same graphs: IPOPT (:mod:`.ipopt`), the
paper's SUMT + Powell (:mod:`.sumt`, :mod:`.powell`, compiled in :mod:`.cpowell`) and the
exact-probability solver (:mod:`.exact`)."""
