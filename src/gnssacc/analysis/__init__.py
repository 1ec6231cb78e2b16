"""What the solutions are worth: scores against truth, consistency verdicts, observability,
aiding theory and the statistics of studies.

Inputs: solutions (:mod:`gnssacc.estimators`), the prepared recording and its truth when it has
one. Outputs: scores (PRMSE and friends), consistency figures and the warnings a user sees,
per-state observability, Monte-Carlo and paired-study statistics.
"""
