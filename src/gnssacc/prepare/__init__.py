"""What the recording says about itself, found once before estimation.

Inputs: the checked run and its quality report (:mod:`gnssacc.checks`), the run configuration,
and a filter pass (handed in by :mod:`gnssacc.pipeline`) for the decisions that need an
innovation likelihood. Outputs: one immutable prepared recording
(:class:`~gnssacc.prepare.prepared.Prepared`): stationary spans, rest noise, the start state and
its yaw, the identified (tuned) noise, the corrections applied with their evidence; every
estimator, the report and the tuner read it.
"""
