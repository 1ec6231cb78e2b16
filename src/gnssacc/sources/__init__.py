"""Readers of recorded runs and the simulator: every way a recording comes in.

Inputs: files (ROS 1 / ROS 2 / MCAP bags, CSV run directories, the KITTI sequence inside the gtsam
wheel) and ``sim:`` specs. Outputs: a :class:`~gnssacc.core.recording.RecordedRun` in SI units,
body Front-Right-Down and NED conventions, one clock, as the file states it (no judgement of
whether the file is plausible: that is :mod:`gnssacc.checks`); synthetic GNSS noise and outages;
simulated runs with known truth, and bag writers for them.
"""
