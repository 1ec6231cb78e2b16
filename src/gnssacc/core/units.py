"""Units at the edges: factors from the configuration's and the display's units to SI.

Inside, everything is SI and radians; these convert the ``_deg``, ``_mg`` and ``_deg_h`` keys and
columns (multiply to get SI).
"""

from __future__ import annotations

import math

#: Radians per degree.
DEG = math.pi / 180.0
#: Standard gravity [m/s^2].
G0 = 9.80665
#: m/s^2 per milli-g.
MG = 1e-3 * G0
#: rad/s per deg/h.
DEG_H = DEG / 3600.0
