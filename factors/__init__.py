"""GTSAM factors of gnssacc (installed as ``gnssacc.factors``)."""

from .accel_factor import accel_error, gnss_accel_factor, smoother_jacobians_from_H_a
from .accel_window_factor import window_accel_error, window_accel_factor
from .gnss_error_factors import gauss_markov_factor, gnss_position_gm_factor
from .gnss_velocity_factor import (
    gnss_velocity_factor,
    preintegrated_velocity_factor,
    velocity_error_jacobians,
    velocity_window_accel_factor,
)
from .preintegrated_position_factor import (
    bridge_covariance,
    preintegrated_position_factor,
    preintegrated_positions_factor,
)
from .prior_factor import joint_prior_factor
from .vehicle_factors import nhc_factor, odometry_factor, vehicle_velocity
from .zero_rate_factor import zero_rate_error, zero_rate_factor

__all__ = [
    "accel_error",
    "bridge_covariance",
    "gauss_markov_factor",
    "gnss_accel_factor",
    "gnss_position_gm_factor",
    "gnss_velocity_factor",
    "joint_prior_factor",
    "nhc_factor",
    "odometry_factor",
    "preintegrated_position_factor",
    "preintegrated_positions_factor",
    "preintegrated_velocity_factor",
    "smoother_jacobians_from_H_a",
    "vehicle_velocity",
    "velocity_error_jacobians",
    "velocity_window_accel_factor",
    "window_accel_error",
    "window_accel_factor",
    "zero_rate_error",
    "zero_rate_factor",
]
