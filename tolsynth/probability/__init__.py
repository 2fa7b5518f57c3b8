"""Error shapes and probabilities, pure maths with no robot in it: the distributions of the
errors inside their bands, the Gaussian reading of the paper (:mod:`.stats`) and the exact
probabilities of the linear error model (:mod:`.exact`)."""
