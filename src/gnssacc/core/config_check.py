"""Type and range of every configuration key, checked before anything is computed.

Each key's type follows its default in :data:`gnssacc.core.config.DEFAULTS` (a bool, an integer, a
number, a string, a table, or a vector: a number or a list of three, or ``[]`` when the default
is ``[]``), unless :data:`KINDS` says otherwise. Numbers must be finite; :data:`BOUNDS` gives
the range of each numeric key (every axis of a vector key) and :data:`CHOICES` the values of a
key that takes one of a few. Zero is allowed only where it means "off" and the code handles it
(e.g. a bias random walk of zero, a known bias of zero sigma, a gate of zero = never); a white
noise density or a sigma the estimator divides by must be positive (:data:`WHY`).
"""

from __future__ import annotations

import math
from dataclasses import dataclass


@dataclass(frozen=True)
class Bound:
    """An interval of numbers; ``None`` leaves that side open to infinity.

    Attributes
    ----------
    lo, hi : float or None
        The ends.
    lo_open, hi_open : bool
        Whether each end is excluded.
    """

    lo: float | None = None
    hi: float | None = None
    lo_open: bool = False
    hi_open: bool = False

    def __contains__(self, x: float) -> bool:
        above = self.lo is None or (x > self.lo if self.lo_open else x >= self.lo)
        below = self.hi is None or (x < self.hi if self.hi_open else x <= self.hi)
        return above and below

    def __str__(self) -> str:
        lo, hi = _num(self.lo), _num(self.hi)
        if self.hi is None:
            return f"{'>' if self.lo_open else '>='} {lo}"
        if self.lo is None:
            return f"{'<' if self.hi_open else '<='} {hi}"
        return f"in {'(' if self.lo_open else '['}{lo}, {hi}{')' if self.hi_open else ']'}"


def _num(x: float | None) -> str:
    """A bound as written by a person: 360, 4294967295, 0.5, 1e-06, 1e+09."""
    if x is None:
        return ""
    power_of_ten = x != 0 and math.log10(abs(x)).is_integer()
    whole = float(x).is_integer() and abs(x) < 1e16 and not (power_of_ten and abs(x) >= 1e5)
    return str(int(x)) if whole else f"{x:g}"


POSITIVE = Bound(0.0, lo_open=True)
NON_NEGATIVE = Bound(0.0)


def _all(section: str, keys: str, bound: Bound) -> dict:
    return {(section, k): bound for k in keys.split()}


#: Range of each numeric key (all axes of a vector key). Keys not listed: any finite number.
BOUNDS: dict[tuple[str, str], Bound] = {
    # White-noise densities must be positive: a real sensor has noise, and a density of 0 tells
    # the estimators to trust the IMU exactly (they then drift tens of metres and every figure
    # reads inconsistent). Instabilities and start-up sigmas may be 0: no bias walk, a known
    # (calibrated) bias; the smoother floors them far below any real IMU where GTSAM needs a
    # non-singular covariance. The correlation time must be positive. The upper ends are far
    # beyond any real sensor; they only keep squares and products finite.
    **_all("imu", "gyro_arw_deg_rth accel_vrw_mps_rth", Bound(0.0, 1e3, lo_open=True)),
    **_all("imu", "gyro_bias_instability_deg_h accel_bias_instability_mg", Bound(0.0, 1e6)),
    **_all("imu", "gyro_bias_sigma0_deg_h accel_bias_sigma0_mg", Bound(0.0, 1e6)),
    ("imu", "bias_correlation_time_s"): Bound(0.0, 1e9, lo_open=True),
    ("imu", "gyro_turn_error_ppm"): Bound(0.0, 1e6),
    ("imu", "accel_misalignment_ppm"): Bound(0.0, 1e6),
    ("gnss", "lever_arm_b_m"): Bound(-1e3, 1e3),
    **_all("gnss", "default_sigma_m gm_tau_s", Bound(0.0, 1e9, lo_open=True)),
    ("gnss", "sigma_scale"): Bound(0.0, 1e6, lo_open=True),
    ("gnss", "nmea_vertical_factor"): Bound(0.0, 100.0, lo_open=True),
    ("gnss", "gm_sigma_m"): Bound(0.0, 1e9),
    ("accel", "window"): Bound(3, 100),
    **_all("accel", "max_gap_s sigma_mps2", POSITIVE),
    ("accel", "specific_force_avg_s"): NON_NEGATIVE,
    **_all(
        "init",
        "pos_sigma_m vel_sigma_mps roll_pitch_sigma_deg yaw_sigma_deg yaw_horizon_s course_fit_s",
        POSITIVE,
    ),
    ("init", "yaw_hypotheses"): Bound(4, 360),
    ("init", "yaw_confidence"): Bound(0.5, 1.0, hi_open=True),
    **_all("init", "roll_pitch_sigma_min_deg vel_sigma_min_mps", NON_NEGATIVE),
    ("ekf", "position_gate_nis"): NON_NEGATIVE,
    **_all("zupt", "interval_s velocity_sigma_mps", POSITIVE),
    ("zupt", "gate_nis"): NON_NEGATIVE,
    **_all("nhc", "interval_s", Bound(0.0, 3600.0, lo_open=True)),
    **_all("nhc", "sigma_lateral_mps sigma_vertical_mps", Bound(0.0, 100.0, lo_open=True)),
    ("nhc", "lever_arm_b_m"): Bound(-1e3, 1e3),
    ("nhc", "pivot_offset_m"): Bound(0.0, 100.0),
    **_all("nhc", "pitch_offset_deg yaw_offset_deg", Bound(-10.0, 10.0)),
    ("velocity", "sigma_scale"): Bound(0.0, 1e6, lo_open=True),
    ("velocity", "gate_nis"): Bound(0.0, 1e9),
    ("velocity", "default_sigma_mps"): Bound(0.0, 1e3, lo_open=True),
    ("odometry", "interval_s"): Bound(0.0, 3600.0),
    ("odometry", "speed_sigma_mps"): Bound(0.0, 100.0, lo_open=True),
    ("odometry", "lever_arm_b_m"): Bound(-1e3, 1e3),
    ("odometry", "scale_sigma"): Bound(0.0, 1.0, lo_open=True),
    ("odometry", "scale_tau_s"): Bound(0.0, 1e9, lo_open=True),
    **_all(
        "stationary",
        "cell_s block_s omega_max_dps z noise_window_s gnss_k_sigma gnss_excursion_k",
        POSITIVE,
    ),
    **_all(
        "stationary",
        "floor_accel_mps2 floor_gyro_dps min_duration_s edge_trim_s gnss_speed_floor_mps "
        "gnss_corr_s gnss_margin_s excursion_floor_mps2 chain_max_gap_s chain_floor_mps "
        "link_reach_s chain_cross_axis chain_margin",
        NON_NEGATIVE,
    ),
    ("stationary", "noise_spread"): Bound(1.0),
    ("stationary", "gap_factor"): Bound(1.0, lo_open=True),
    ("stationary", "gnss_min_fixes"): Bound(2),
    **_all("tune", "prior_decades stationary_prior_decades", POSITIVE),
    ("tune", "max_evaluations"): Bound(1, 100_000),
    ("tune", "cov_every"): Bound(1, 10_000),
    **_all("smoother", "lag_s max_node_spacing_s", POSITIVE),
    **_all("smoother", "relinearize_threshold integration_sigma min_node_spacing_s", NON_NEGATIVE),
    ("smoother", "relinearize_skip"): Bound(1),
    **_all("quality", "interp_min_s suspect_local_window_s", POSITIVE),
    **_all("quality", "interp_tol suspect_gyro_sigma_dps suspect_accel_sigma_mps2", NON_NEGATIVE),
    ("quality", "gap_factor"): Bound(1.0, lo_open=True),
    ("quality", "stuck_min_samples"): Bound(2),
    ("data", "max_bad_fraction"): Bound(0.0, 1.0),
}

#: Why a key must be positive, for the error line (a key not listed: its range says enough).
WHY = {
    **dict.fromkeys(
        (("imu", "gyro_arw_deg_rth"), ("imu", "accel_vrw_mps_rth")),
        "a white-noise density of 0 tells the estimators the IMU has no noise; write the "
        "sensor's datasheet value, or leave the key out and let --tune auto identify it",
    ),
    **dict.fromkeys(
        (("gnss", "default_sigma_m"), ("gnss", "sigma_scale")),
        "a fix sigma of 0 tells the estimators a fix is exact",
    ),
}

#: Keys that take one of a few values (strings are compared case-insensitively where the code does).
CHOICES: dict[tuple[str, str], tuple] = {
    ("ekf", "phi_order"): (1, 2),
    ("quality", "suspect_sigma_mode"): ("local", "fixed"),
    ("smoother", "factorization"): ("QR", "CHOLESKY"),
    ("tune", "mode"): ("auto", "none"),
    ("tune", "likelihood"): ("position", "position+accel"),
    ("checks", "repair"): ("never", "auto"),
    ("checks", "on_proof"): ("apply", "refuse"),
}
#: Choices compared in upper case (the code upper-cases the value).
UPPER_CASE = {("smoother", "factorization")}

#: Fields of a ``[bag.fix_mappings."pkg/msg/Type"]`` table (see :data:`gnssacc.sources.rosbag.FIX_MAPPINGS`):
#: message field paths, non-zero scale factors, and the status values that mean "no fix".
FIX_MAPPING_FIELDS = {
    **dict.fromkeys(
        ("lat", "lon", "height", "sigma_n", "sigma_e", "sigma_d", "stamp", "status"), "path"
    ),
    **dict.fromkeys(("latlon_scale_deg", "height_scale_m", "sigma_scale_m"), "scale"),
    "no_fix_values": "list",
}

#: Kinds that do not follow the default's type.
KINDS: dict[tuple[str, str], str] = {
    # per-axis keys with a scalar default (a number, or x, y, z / N, E, D values)
    **dict.fromkeys(
        [
            ("imu", k)
            for k in (
                "gyro_arw_deg_rth",
                "accel_vrw_mps_rth",
                "gyro_bias_instability_deg_h",
                "accel_bias_instability_mg",
                "gyro_bias_sigma0_deg_h",
                "accel_bias_sigma0_mg",
            )
        ]
        + [("gnss", "gm_sigma_m"), ("gnss", "gm_tau_s")],
        "vector",
    ),
    ("mounting", "imu_to_body_rpy_deg"): "vector or auto",
    ("mounting", "imu_time_offset_s"): "number or auto",
    ("imu", "gyro_turn_error_ppm"): "number or auto",
    ("imu", "accel_misalignment_ppm"): "number or auto",
    ("init", "roll_pitch_sigma_deg"): "number or empty",
    ("init", "yaw_sigma_deg"): "number or empty",
    ("gnss", "quality"): "quality map",
    ("gnss", "nmea_uere_m"): "quality map",
}
#: Names a ``quality map`` key takes (:data:`gnssacc.core.recording.FIX_QUALITY`).
QUALITY_NAMES = ("fix", "float", "sbas", "dgps", "single", "ppp", "estimated", "unknown")
#: Largest factor or UERE of a quality map (keeps squares finite).
_QUALITY_MAX = 1e6


def kind_of(section: str, key: str, default) -> str:
    """The kind of value ``[section] key`` takes: from :data:`KINDS`, else from its default."""
    if (section, key) in KINDS:
        return KINDS[(section, key)]
    if isinstance(default, bool):
        return "bool"
    if isinstance(default, int):
        return "int"
    if isinstance(default, float):
        return "number"
    if isinstance(default, str):
        return "string"
    if isinstance(default, dict):
        return "table"
    return "vector" if default else "vector or empty"


def check_value(section: str, key: str, value, default) -> str | None:
    """What is wrong with ``value`` for ``[section] key``, or ``None`` when it is fine.

    Parameters
    ----------
    section, key : str
    value
        The value as read from TOML.
    default
        The key's built-in default (gives the kind, see :func:`kind_of`).

    Returns
    -------
    str or None
        ``"[section] key: <problem> (expected <kind and range>)"``.
    """
    kind = kind_of(section, key, default)
    bound, choices = BOUNDS.get((section, key)), CHOICES.get((section, key))
    if (section, key) in UPPER_CASE and isinstance(value, str):
        value = value.upper()
    if kind == "quality map":
        problem = quality_map_problem(value, drop_allowed=key == "quality")
        return None if problem is None else f"[{section}] {key}: {problem}"
    problem = _problem(kind, value, bound, choices)
    if problem is None:
        return mappings_problem(value) if (section, key) == ("bag", "fix_mappings") else None
    why = WHY.get((section, key))
    return f"[{section}] {key}: {problem} (expected {expectation(kind, bound, choices)})" + (
        f": {why}" if why else ""
    )


def quality_map_problem(value, drop_allowed: bool) -> str | None:
    """What is wrong with a table of fix qualities (:data:`QUALITY_NAMES`) -> positive numbers
    (or ``"drop"`` where ``drop_allowed``), or ``None``."""
    what = 'a positive number or "drop"' if drop_allowed else "a positive number"
    if not isinstance(value, dict):
        example = '"drop"' if drop_allowed else "3.0"
        return f"{show(value)} is not a table (expected e.g. {{ single = {example} }})"
    for name, v in value.items():
        if name not in QUALITY_NAMES:
            return f"unknown fix quality {name!r} (known: {', '.join(QUALITY_NAMES)})"
        if drop_allowed and v == "drop":
            continue
        if number_problem(v, False, Bound(0.0, _QUALITY_MAX, lo_open=True)):
            return f"{name} = {show(v)} (expected {what})"
    return None


def mappings_problem(mappings: dict) -> str | None:
    """What is wrong with the ``[bag] fix_mappings`` tables (:data:`FIX_MAPPING_FIELDS`), or ``None``."""
    for typ, mapping in mappings.items():
        where = f'[bag.fix_mappings."{typ}"]'
        for key, value in mapping.items():
            kind = FIX_MAPPING_FIELDS.get(key)
            if kind is None:
                return f"{where}: unknown key {key!r} (known: {', '.join(FIX_MAPPING_FIELDS)})"
            if kind == "path" and not (isinstance(value, str) and value.strip()):
                return f'{where} {key}: {show(value)} is not a field path (expected a string such as "fix.lat")'
            if kind == "scale" and (number_problem(value, False, None) or value == 0):
                return f"{where} {key}: {show(value)} is not a usable factor (expected a non-zero number)"
            if kind == "list" and not isinstance(value, list):
                return f"{where} {key}: {show(value)} is not a list (expected e.g. [-1])"
    return None


def _problem(kind: str, value, bound: Bound | None, choices: tuple | None) -> str | None:
    if (kind.endswith(" or auto") and value == "auto") or (
        kind.endswith(" or empty") and value == []
    ):
        return None
    base = kind.split(" or ")[0]
    if base == "bool":
        return None if isinstance(value, bool) else f"{show(value)} is not true or false"
    if base == "table":
        if not isinstance(value, dict):
            return f"{show(value)} is not a table"
        bad = [k for k, v in value.items() if not isinstance(v, dict)]
        return f"entry {bad[0]!r} is not a table" if bad else None
    if base == "string":
        if not isinstance(value, str):
            return f"{show(value)} is not a string"
        return None if choices is None or value in choices else f"unknown value {show(value)}"
    if base == "vector" and isinstance(value, list):
        if len(value) not in (1, 3):
            return f"a list of {len(value)} values, not 3"
        return next((p for p in (number_problem(v, False, bound) for v in value) if p), None)
    problem = number_problem(value, base == "int", bound)
    if problem is None and choices is not None and value not in choices:
        return f"{show(value)} is not allowed"
    return problem


def number_problem(value, integer: bool, bound: Bound | None) -> str | None:
    """What is wrong with a number (type, finiteness, whole, range), or ``None``."""
    if isinstance(value, bool) or not isinstance(value, (int, float)):
        return f"{show(value)} is not a number"
    if not math.isfinite(value):
        return f"{show(value)} is not a finite number"
    if integer and not isinstance(value, int):
        return f"{show(value)} is not a whole number"
    if bound is not None and value not in bound:
        return f"{show(value)} is out of range"
    return None


def expectation(kind: str, bound: Bound | None, choices: tuple | None) -> str:
    """Plain words for what a key of this kind, range and choices takes."""
    if choices is not None:
        return "one of " + ", ".join(show(c) for c in choices)
    base = kind.split(" or ")[0]
    rng = f" {bound}" if bound is not None else ""
    text = {
        "bool": "true or false",
        "table": "a table of tables",
        "string": "a string",
        "int": f"a whole number{rng}",
        "number": f"a number{rng}",
        "vector": f"a number{rng} or a list of three such numbers",
    }[base]
    if kind.endswith(" or empty"):
        text = f"[] (not set) or {text}"
    if kind.endswith(" or auto"):
        text = f'{text}, or "auto"'
    return text


def show(value) -> str:
    """A value as it would be written in TOML (strings quoted), shortened."""
    if isinstance(value, bool):
        text = "true" if value else "false"
    elif isinstance(value, str):
        text = '"' + value + '"'
    else:
        text = repr(value)
    return text if len(text) <= 60 else text[:57] + "..."


#: Largest seed (numpy takes more, but a 32-bit seed is plenty and portable).
MAX_SEED = 2**32 - 1
