"""Names and display units of the error states and the trajectory outputs (the one table the CSV
files, the report, the observability analysis and the text tables read), and the text-table
layout every printed table uses.

Inside, everything is SI and radians (:class:`gnssacc.core.solution.NavSolution`); at these edges the
attitude is in degrees, the accelerometer bias in milli-g and the gyro bias in deg/h, as in the
configuration keys (``_deg``, ``_mg``, ``_deg_h``).
"""

from __future__ import annotations

import numpy as np

from .states import ATT, BA, BG, BIASES, POS, VEL
from .units import G0

RAD2DEG = 180.0 / np.pi
RPS2DPH = RAD2DEG * 3600.0  # rad/s -> deg/h
MPS2_TO_MG = 1e3 / G0  # m/s^2 -> milli-g

#: The 15 error states in the filter's order: (name, estimate column, sigma column, unit, factor
#: from SI). Biases have estimate columns; position, velocity and attitude have theirs in
#: :data:`TRAJECTORY_HEAD` (lat/lon/h, vn/ve/vd, roll/pitch/yaw).
STATES = (
    ("pos_n", None, "sn_m", "m", 1.0),
    ("pos_e", None, "se_m", "m", 1.0),
    ("pos_d", None, "sd_m", "m", 1.0),
    ("vel_n", None, "svn_mps", "m/s", 1.0),
    ("vel_e", None, "sve_mps", "m/s", 1.0),
    ("vel_d", None, "svd_mps", "m/s", 1.0),
    ("roll", None, "sroll_deg", "deg", RAD2DEG),
    ("pitch", None, "spitch_deg", "deg", RAD2DEG),
    ("yaw", None, "syaw_deg", "deg", RAD2DEG),
    ("ba_x", "bax_mg", "sbax_mg", "mg", MPS2_TO_MG),
    ("ba_y", "bay_mg", "sbay_mg", "mg", MPS2_TO_MG),
    ("ba_z", "baz_mg", "sbaz_mg", "mg", MPS2_TO_MG),
    ("bg_x", "bgx_dph", "sbgx_dph", "deg/h", RPS2DPH),
    ("bg_y", "bgy_dph", "sbgy_dph", "deg/h", RPS2DPH),
    ("bg_z", "bgz_dph", "sbgz_dph", "deg/h", RPS2DPH),
)
STATE_NAMES = tuple(s[0] for s in STATES)
SIGMA_COLUMNS = tuple(s[2] for s in STATES)
DISPLAY_UNITS = tuple(s[3] for s in STATES)
#: Factors from SI to :data:`DISPLAY_UNITS`, per state.
DISPLAY_SCALE = np.array([s[4] for s in STATES])
#: The columns of ``trajectory_<id>.csv``: time, position, velocity, attitude, biases, 1-sigmas.
TRAJECTORY_HEAD = [
    "t",
    "lat_deg",
    "lon_deg",
    "h_m",
    "vn",
    "ve",
    "vd",
    "roll_deg",
    "pitch_deg",
    "yaw_deg",
]
TRAJECTORY_COLUMNS = TRAJECTORY_HEAD + [s[1] for s in STATES[BIASES]] + list(SIGMA_COLUMNS)
#: Groups of three states for figures: (title, slice of the state vector, unit, axis labels).
STATE_GROUPS = (
    ("position", POS, "m", ("N", "E", "D")),
    ("velocity", VEL, "m/s", ("N", "E", "D")),
    ("attitude", ATT, "deg", ("roll", "pitch", "yaw")),
    ("accelerometer bias", BA, "mg", ("x", "y", "z")),
    ("gyro bias", BG, "deg/h", ("x", "y", "z")),
)


def text_table(head: list[str], rows: list[list[str]], min_first: int = 0) -> list[str]:
    """Lines of a plain-text table: the first column left-aligned, the others right-aligned, each
    as wide as its widest cell (the first at least ``min_first``), a dashed rule under the head."""
    widths = [max(len(str(r[i])) for r in rows + [head]) for i in range(len(head))]
    widths[0] = max(widths[0], min_first)
    line = lambda r: "  ".join(
        str(c).rjust(w) if i else str(c).ljust(w) for i, (c, w) in enumerate(zip(r, widths))
    )
    return [line(head), line(["-" * w for w in widths])] + [line(r) for r in rows]
