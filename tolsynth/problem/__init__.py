"""One tolerance problem: its resolved specification (:mod:`.specification`), the smooth NLP on
CasADi graphs with its dual certificate (:mod:`.nlp`), and the result type (:mod:`.result`)."""
