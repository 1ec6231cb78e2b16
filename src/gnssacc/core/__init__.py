"""The small core every stage stands on: the recording model, configuration, frames and units.

Inputs: nothing of the other stages (it imports none of them). Outputs: the data types that flow
between the stages (:class:`~gnssacc.core.recording.RecordedRun` with its IMU, GNSS, truth and
metadata; :class:`~gnssacc.core.solution.NavSolution`), the run configuration
(:class:`~gnssacc.core.config.RunConfig`, its checks and documentation), WGS-84 earth model and
rotations, errors and warnings, progress display, interrupt handling, memory release, and where
numba caches compiled kernels.
"""
