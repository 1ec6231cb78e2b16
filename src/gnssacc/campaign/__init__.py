"""Many runs at once: batch campaigns, their summaries, and Dask for work beyond one machine.

Inputs: sources, seeds and settings of a campaign, and the single-run pipeline
(:mod:`gnssacc.pipeline`) handed in by the CLI. Outputs: a campaign folder of per-task results
(resumable) and its summary tables and figures.
"""
