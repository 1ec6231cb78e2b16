"""What a user reads and feeds to other tools.

Inputs: solutions, scores and consistency figures (:mod:`gnssacc.analysis`) and the prepared
recording. Outputs: the comparison table, ``metrics.json``, trajectory CSV, TUM and bag exports,
figures, the HTML report, all written through one transactional output folder
(:class:`~gnssacc.outputs.outdir.ResultDir`: the old complete result or the new one, never half).
"""
