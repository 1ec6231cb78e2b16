"""Input checks: units, clocks, coordinates, mounting, GNSS and IMU data quality, from the data alone.

Inputs: a :class:`~gnssacc.core.recording.RecordedRun` as a source delivered it and the run
configuration. Outputs: findings (:class:`~gnssacc.checks.findings.Finding`) with their evidence,
the run with the repairs the evidence allows applied, and the IMU data-quality report
(:class:`~gnssacc.checks.quality.QualityReport`: gaps, interpolated and damaged spans). A check
uses no estimator directly; where a verdict needs the estimator's likelihood it is handed a
filter pass by the caller.
"""
