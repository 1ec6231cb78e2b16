"""The navigation error states: their blocks and where each sits, named once.

The paper's fifteen states, in this order, are both the estimators' navigation error state
(estimate minus truth; :mod:`gnssacc.estimators.layout` adds the optional states after them) and
the columns of a solution's 1-sigma (:attr:`gnssacc.core.solution.NavSolution.sigma`):

    position error N, E, D [m] | velocity N, E, D [m/s] | attitude [rad] | accelerometer bias
    [m/s^2, body] | gyro bias [rad/s, body]

The attitude block is the small-angle error ``phi`` in the estimators (NED) and roll, pitch, yaw
in a solution. The integer offsets are plain module constants so that numba kernels can use them
as compile-time constants.
"""

from __future__ import annotations

#: Offset of each three-entry block: position, velocity, attitude, accelerometer bias, gyro bias.
I_POS, I_VEL, I_ATT, I_BA, I_BG = 0, 3, 6, 9, 12
#: Entries per block.
BLOCK = 3
#: Number of navigation states.
N_NAV = 15

POS = slice(I_POS, I_POS + BLOCK)
VEL = slice(I_VEL, I_VEL + BLOCK)
ATT = slice(I_ATT, I_ATT + BLOCK)
BA = slice(I_BA, I_BA + BLOCK)
BG = slice(I_BG, I_BG + BLOCK)
#: Roll and pitch, and yaw, in a solution's attitude block.
TILT = slice(I_ATT, I_ATT + 2)
YAW = slice(I_ATT + 2, I_ATT + 3)
#: Position, velocity and attitude (the states a truth gives).
MOTION = slice(I_POS, I_ATT + BLOCK)
#: Both biases (accelerometer, then gyro).
BIASES = slice(I_BA, I_BG + BLOCK)
#: All navigation states.
NAV = slice(0, N_NAV)
#: The blocks by name, in state order.
BLOCKS = {"position": POS, "velocity": VEL, "attitude": ATT, "accel_bias": BA, "gyro_bias": BG}
