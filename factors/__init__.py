"""GTSAM factors of gnssacc (installed as ``gnssacc.factors``)."""
from .accel_factor import accel_error, gnss_accel_factor, smoother_jacobians_from_H_a

__all__ = ["accel_error", "gnss_accel_factor", "smoother_jacobians_from_H_a"]
