"""gnssacc: INS/GNSS state estimation with GNSS-derived acceleration aiding.

Implements the error-state EKF of Versano & Klein, "Enhanced INS/GNSS State Estimation using
GNSS-Based Acceleration Measurements", with recorded-run ingestion, metrics and reports.
"""
__version__ = "0.1.0"

from .jit import configure_cache as _configure_cache

_configure_cache()   # before anything imports numba: a read-only install caches in the user's folder
