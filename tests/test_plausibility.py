"""Input checks (:mod:`gnssacc.checks.plausibility` and the modules it runs) against simulated runs whose
truth is known: every corruption is made here from a clean run, so the expected repair is the
clean run itself, and the value a message tells the user to write is checked by writing it
(through the sources' own :func:`gnssacc.sources.common.apply_mounting`), not by its text.

Both a car (120 s) and the slow UGV (180 s: parked at start and end, reversing, turning on the
spot; its slope-based checks need three minutes of its gentle turns) are used. Cases already in
``test_bad_inputs.py`` (malformed files and config) and ``test_mounting.py`` (a mounting and
offset written in the config) are not repeated.
"""

from __future__ import annotations

import json
import re
import warnings
from dataclasses import replace

import numpy as np
import pytest

from gnssacc import cli
from gnssacc.checks.plausibility import CHECKS, fix_imu_time_units
from gnssacc.core.config import load_config
from gnssacc.core.earth import LocalTangentFrame
from gnssacc.core.errors import DataWarning, InputError
from gnssacc.core.recording import ImuData, InitialState
from gnssacc.core.rotations import euler_to_dcm
from gnssacc.pipeline import check_input
from gnssacc.sources.common import apply_mounting
from gnssacc.sources.csvdir import load_csv_run, write_csv_run
from gnssacc.sources.sim import simulate

DURATION_S = {"car": 120.0, "ugv-slow": 180.0}
SCENARIOS = list(DURATION_S)
GRADES = ("consumer", "industrial", "tactical")
SEED = 11
G0 = 9.80665
RUN_DIR = "rundir"  # where the runs below claim to come from (a CSV run directory)
AUTO_MOUNT = {"mounting": {"imu_to_body_rpy_deg": "auto"}}
AUTO_OFFSET = {"mounting": {"imu_time_offset_s": "auto"}}
REPAIR = {"checks": {"repair": "auto"}}
#: Today's refusal of a proven correction (``--strict``); the default applies it.
STRICT = {"on_proof": "refuse"}


# --- runs ---------------------------------------------------------------------------------------------


def _as_csv(run):
    """The run as if loaded from the CSV run directory ``RUN_DIR`` (so messages name its files)."""
    return replace(run, where=RUN_DIR, meta={**run.meta, "source": "csv"})


def _rtk(run, sigma_m: float, seed: int):
    """The run's fixes replaced by truth + white noise of ``sigma_m`` N/E (1.6x that down), with
    matching sigmas: RTK-grade fixes (``run`` simulated with ``noise="none"``)."""
    g = run.gnss
    sig = np.array([sigma_m, sigma_m, 1.6 * sigma_m])
    p = (
        run.origin.to_ned(g.lat, g.lon, g.h)
        + np.random.default_rng(seed).normal(size=(len(g), 3)) * sig
    )
    lat, lon, h = run.origin.to_llh(p)
    return replace(run, gnss=replace(g, lat=lat, lon=lon, h=h, sigma_ned=np.tile(sig, (len(g), 1))))


@pytest.fixture(scope="module")
def sims():
    """``sims(scenario, grade="consumer", noise="white", seed=SEED)``: one simulation per
    combination, shared by the whole module, as a run loaded from ``RUN_DIR``. ``noise="rtk"``:
    5 cm fixes."""
    cache = {}

    def get(scenario, grade="consumer", noise="white", seed=SEED):
        key = (scenario, grade, noise, seed)
        if key not in cache:
            sim_noise = "none" if noise == "rtk" else noise
            run = simulate(
                scenario, DURATION_S[scenario], imu_grade=grade, noise=sim_noise, seed=seed
            )
            cache[key] = _as_csv(_rtk(run, 0.05, seed + 1) if noise == "rtk" else run)
        return cache[key]

    return get


def _imu(run, t=None, f=None, w=None):
    i = run.imu
    return replace(
        run,
        imu=ImuData(
            i.t if t is None else t, i.f_b if f is None else f, i.omega_ib_b if w is None else w
        ),
    )


def _fixes(run, lat, lon, h=None):
    """Other fix coordinates, with the tangent plane at the first fix (as every loader does)."""
    g = replace(run.gnss, lat=lat, lon=lon, h=run.gnss.h if h is None else h)
    return replace(run, gnss=g, origin=LocalTangentFrame(g.lat[0], g.lon[0], g.h[0]))


def _rotated(run, R):
    """What an IMU turned by ``R`` logs: each body-frame vector ``x`` appears as ``R x``."""
    return _imu(run, f=run.imu.f_b @ R.T, w=run.imu.omega_ib_b @ R.T)


def _check(run, **overrides):
    """``check_run`` with a configuration of ``overrides``: (run, cfg, findings, warning texts)."""
    cfg = load_config(overrides=overrides or None)
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        out, cfg_out, findings = check_input(run, cfg)
    texts = [str(w.message) for w in caught if issubclass(w.category, DataWarning)]
    return out, cfg_out, findings, texts


def _error(run, **overrides) -> InputError:
    """The refusal of ``run`` with ``overrides`` (``[checks] on_proof = "refuse"`` unless they set
    it: a proven correction is otherwise applied)."""
    overrides = {**overrides, "checks": {**STRICT, **overrides.get("checks", {})}}
    with pytest.raises(InputError) as exc:
        _check(run, **overrides)
    assert "never shows a speed above" not in str(exc.value)
    return exc.value


def _value_after(text: str, key: str) -> str:
    m = re.search(re.escape(key) + r" = (\[[^\]]*\]|[-+0-9.e]+)", text)
    assert m, (key, text)
    return m.group(1)


def _max_angle_deg(a: np.ndarray, b: np.ndarray) -> float:
    """Largest angle between corresponding rows of ``a`` and ``b`` (rows of non-zero norm) [deg]."""
    na, nb = np.linalg.norm(a, axis=1), np.linalg.norm(b, axis=1)
    use = (na > 1e-6) & (nb > 1e-6)
    cos = np.sum(a[use] * b[use], axis=1) / (na[use] * nb[use])
    return float(np.degrees(np.arccos(np.clip(cos, -1.0, 1.0))).max())


# --- 1. clean runs: no false alarms --------------------------------------------------------------------


@pytest.mark.parametrize("grade", GRADES)
@pytest.mark.parametrize("scenario", SCENARIOS)
def test_clean_run_passes_untouched(scenario, grade, sims):
    run = sims(scenario, grade)
    out, cfg, findings, texts = _check(run)
    assert out is run and findings == [] and texts == []
    assert cfg["mounting"] == load_config()["mounting"]


@pytest.mark.parametrize("scenario", SCENARIOS)
def test_clean_run_with_everything_automatic_is_left_as_it_is(scenario, sims):
    """Repairs allowed, mounting and clock offset measured: nothing repaired, the identity mounting,
    and no offset applied: the estimator does not find the stamps improved by any (its measurement
    is consistent with the true 0)."""
    run = sims(scenario)
    out, cfg, findings, _ = _check(
        run,
        checks={"repair": "auto"},
        mounting={"imu_to_body_rpy_deg": "auto", "imu_time_offset_s": "auto"},
    )
    assert sorted(f.check for f in findings) == ["mounting", "time_offset"]
    assert next(f for f in findings if f.check == "mounting").action == "kept"
    np.testing.assert_array_equal(cfg["mounting"]["imu_to_body_rpy_deg"], [0.0, 0.0, 0.0])
    np.testing.assert_array_equal(out.imu.f_b, run.imu.f_b)
    off = next(f for f in findings if f.check == "time_offset")
    assert off.action in ("refuted", "not confirmed", "noted"), off
    if "measured_s" in off.details:
        assert abs(off.details["measured_s"]) <= max(3.0 * off.details["sigma_s"], 0.02), (
            off.details
        )
    assert cfg["mounting"]["imu_time_offset_s"] == 0.0
    np.testing.assert_array_equal(out.imu.t, run.imu.t)


# --- 2-4. IMU units ----------------------------------------------------------------------------------------


@pytest.mark.parametrize("scenario", SCENARIOS)
def test_accelerometer_in_g(scenario, sims):
    run = sims(scenario)
    bad = _imu(run, f=run.imu.f_b / G0)
    err = _error(bad)
    assert err.where == f"{RUN_DIR}/imu.csv"
    assert "in g" in err.problem and "9.80665" in err.problem
    assert 'on_proof = "refuse"' in err.problem
    out, _, findings, texts = _check(bad)  # by default a proven repair is applied, and recorded
    np.testing.assert_allclose(out.imu.f_b, run.imu.f_b, rtol=1e-12, atol=1e-12)
    np.testing.assert_array_equal(out.imu.omega_ib_b, run.imu.omega_ib_b)
    np.testing.assert_array_equal(out.imu.t, run.imu.t)
    assert [(f.check, f.action) for f in findings] == [("accel_units", "repaired")]
    assert findings[0].where == f"{RUN_DIR}/imu.csv" and "9.80665" in findings[0].repaired
    assert findings[0].details["verdict"]["decisive"] and texts == []


@pytest.mark.parametrize("scenario", SCENARIOS)
def test_gyro_in_degrees_per_second(scenario, sims):
    run = sims(scenario)
    bad = _imu(run, w=np.degrees(run.imu.omega_ib_b))
    err = _error(bad)
    assert err.where == f"{RUN_DIR}/imu.csv" and "deg/s" in err.problem and "pi/180" in err.problem
    out, _, findings, texts = _check(bad)
    np.testing.assert_allclose(out.imu.omega_ib_b, run.imu.omega_ib_b, rtol=1e-12, atol=1e-15)
    np.testing.assert_array_equal(out.imu.f_b, run.imu.f_b)
    assert [(f.check, f.action) for f in findings] == [("gyro_units", "repaired")]
    assert "pi/180" in findings[0].repaired and texts == []
    with pytest.raises(InputError):  # repairs of units refused on request
        _check(bad, checks={"repair": "never"})


def test_gyro_in_degrees_per_second_on_a_parked_vehicle_is_proven_by_the_estimator(sims):
    """Little turning, no verdict from the slope: the rest rate proposes deg/s, and the estimator
    proves it (a parked vehicle whose gyro reads several deg/s as "rad/s" would spin its attitude):
    an error with the evidence, repaired when allowed."""
    run = _as_csv(simulate("static", 120.0, imu_grade="consumer", noise="white", seed=SEED))
    spun = _imu(run, w=np.degrees(run.imu.omega_ib_b) + np.array([0.0, 0.0, 5.0]))  # a 5 deg/s bias
    err = _error(spun)
    assert err.where == f"{RUN_DIR}/imu.csv" and "deg/s" in err.problem and "at rest" in err.problem
    assert "the estimator proves it" in err.problem
    out, _, findings, _ = _check(spun)
    assert [(f.check, f.action) for f in findings] == [("gyro_units", "repaired")]
    np.testing.assert_allclose(out.imu.omega_ib_b, np.radians(spun.imu.omega_ib_b), rtol=1e-12)


@pytest.mark.parametrize(
    "unit, scale, divisor",
    [("milliseconds", 1e3, "1000"), ("microseconds", 1e6, "1e6"), ("nanoseconds", 1e9, "1e9")],
)
@pytest.mark.parametrize("scenario", SCENARIOS)
def test_imu_time_stamps_not_in_seconds(scenario, unit, scale, divisor, sims):
    run = sims(scenario)
    bad = _imu(run, t=run.imu.t * scale)
    err = _error(bad)
    assert err.where == f"{RUN_DIR}/imu.csv" and unit in err.problem
    assert f"divide the t column by {divisor}" in err.problem
    out, _, findings, texts = _check(bad)
    np.testing.assert_allclose(out.imu.t, run.imu.t, rtol=1e-12, atol=1e-9)
    assert [(f.check, f.action) for f in findings] == [("time_units", "repaired")]
    assert f"divided the IMU time stamps by {divisor}" in findings[0].repaired and texts == []


def test_fix_imu_time_units_for_sources_on_unix_epoch_stamps(sims):
    """What a source calls before the IMU and the fixes must overlap: IMU stamps in ns since the
    Unix epoch beside fixes in s since the epoch."""
    run = sims("car")
    t0 = 1.7e9
    t_gnss = run.gnss.t + t0
    ns = ImuData((run.imu.t + t0) * 1e9, run.imu.f_b, run.imu.omega_ib_b)
    with pytest.raises(InputError) as exc:
        fix_imu_time_units(ns, t_gnss, "imu.csv", load_config(overrides={"checks": STRICT}))
    assert exc.value.where == "imu.csv" and "nanoseconds" in exc.value.problem
    assert 'on_proof = "refuse"' in exc.value.problem
    with pytest.warns(DataWarning, match="divided the IMU time stamps by 1e9"):
        fixed = fix_imu_time_units(ns, t_gnss, "imu.csv", load_config())
    np.testing.assert_allclose(fixed.t - t0, run.imu.t, atol=1e-6)
    seconds = ImuData(run.imu.t + t0, run.imu.f_b, run.imu.omega_ib_b)
    assert fix_imu_time_units(seconds, t_gnss, "imu.csv", load_config()) is seconds


def test_gnss_time_stamps_in_milliseconds(sims):
    run = sims("car")
    err = _error(replace(run, gnss=replace(run.gnss, t=run.gnss.t * 1000.0)))
    assert err.where == f"{RUN_DIR}/gnss.csv" and "not in seconds" in err.problem


@pytest.mark.parametrize("scenario", SCENARIOS)
@pytest.mark.slow
def test_unit_and_layout_errors_found_whatever_the_draw(scenario):
    """Six more seeds (IMU errors and fix noise) per vehicle: each corruption is found by its own
    check and none of the clean runs is flagged. (A slope-precision gate of 15 % missed the slow
    UGV's deg/s gyro at 16 %; a slope band around -1 missed its swapped fixes, which the swap
    also stretches by cos(lat)/cos(lon).)"""
    cases = {
        "accel_units": lambda r: _imu(r, f=r.imu.f_b / G0),
        "gyro_units": lambda r: _imu(r, w=np.degrees(r.imu.omega_ib_b)),
        "time_units": lambda r: _imu(r, t=r.imu.t * 1000.0),
        "latlon": lambda r: _fixes(r, r.gnss.lon, r.gnss.lat),
    }
    words = {
        "accel_units": "in g",
        "gyro_units": "deg/s",
        "time_units": "milliseconds",
        "latlon": "mirror image",
    }
    for seed in range(6):
        run = _as_csv(
            simulate(
                scenario, DURATION_S[scenario], imu_grade=GRADES[seed % 3], noise="white", seed=seed
            )
        )
        assert _check(run)[2] == []
        for check, corrupt in cases.items():
            assert words[check] in _error(corrupt(run)).problem, (seed, check)


# --- 5. clock offset ---------------------------------------------------------------------------------------
# The offset is what [mounting] imu_time_offset_s means: ADDED to the IMU stamps it puts them on
# the GNSS clock. An IMU stamping on UTC beside fixes on GPS time logs t_gps - 18: offset +18.


def _late_clock(run, offset_s):
    """The IMU as logged by a clock that needs ``offset_s`` added to reach the GNSS clock."""
    return _imu(run, t=run.imu.t - offset_s)


@pytest.mark.parametrize("offset_s", [0.1, 1.0, 18.0, -1.0])
@pytest.mark.parametrize("scenario", SCENARIOS)
def test_auto_clock_offset_within_20_ms(scenario, offset_s, sims):
    """Acceptance: offsets of 0.1 s, 1 s and 18 s (and a negative one) recovered within 20 ms.
    With fixes precise enough for 20 ms to mean something (5 cm; 20 ms is 3 cm at the UGV's
    1.5 m/s, against 3 m of ordinary fix noise) and an industrial IMU."""
    run = sims(scenario, "industrial", "rtk")
    out, cfg, findings, texts = _check(_late_clock(run, offset_s), **AUTO_OFFSET)
    applied = cfg["mounting"]["imu_time_offset_s"]
    assert abs(applied - offset_s) <= 0.020, (applied, offset_s)
    np.testing.assert_allclose(out.imu.t, run.imu.t, atol=0.020)
    assert [(f.check, f.action) for f in findings] == [("time_offset", "applied")]
    assert findings[0].where == f"{RUN_DIR}/imu.csv" and texts == []
    assert 'imu_time_offset_s = "auto"' in findings[0].problem


@pytest.mark.parametrize("scenario, seed", [("car", SEED), ("ugv-slow", SEED), ("ugv-slow", 2)])
def test_auto_clock_offset_with_ordinary_fixes_is_within_its_sigma(scenario, seed, sims):
    """3 m fixes: the 18 s is found, within three of the sigma it reports (at most 0.3 s). (The
    slow UGV's seed 2 has a log-likelihood jagged by ~1.5 over 20 ms: a sigma taken from that
    scale claimed 12 ms for a 0.2 s error.)"""
    run = sims(scenario, seed=seed)
    out, cfg, findings, _ = _check(_late_clock(run, 18.0), **AUTO_OFFSET)
    d = findings[0].details
    assert d["sigma_s"] <= 0.3
    assert abs(cfg["mounting"]["imu_time_offset_s"] - 18.0) <= 3.0 * d["sigma_s"]


@pytest.mark.parametrize("scenario, offset_s", [("car", 18.0), ("ugv-slow", 18.0), ("car", -1.0)])
def test_clock_offset_contradicting_the_configuration(scenario, offset_s, sims):
    """With the default 0 the offset is an error naming the line that fixes it; written into the
    configuration, that line puts the IMU on the GNSS clock."""
    run = sims(scenario)
    bad = _late_clock(run, offset_s)
    err = _error(bad)
    assert err.where == f"{RUN_DIR}/imu.csv" and "[mounting] imu_time_offset_s" in err.problem
    assert ("behind" if offset_s > 0 else "ahead of") in err.problem
    value = float(_value_after(err.problem, "set [mounting] imu_time_offset_s"))
    assert abs(value - offset_s) <= 0.5, value
    line = {"mounting": {"imu_time_offset_s": value}}
    fixed = replace(
        bad, imu=apply_mounting(bad.imu, load_config(overrides=line))
    )  # as a source loads it
    np.testing.assert_allclose(fixed.imu.t, run.imu.t, atol=0.5)
    _, _, findings, _ = _check(fixed, **line)  # ... and it passes
    assert findings == []


def test_auto_clock_offset_is_not_held_at_the_first_guess():
    """A clean slow-UGV run whose cross-correlation puts the offset at -1.5 s: the likelihood must
    be free to move away from it (a filter started before the shifted IMU's first sample pays for
    every later shift, which held the estimate at -1.51 +- 0.05 s)."""
    run = _as_csv(simulate("ugv-slow", 120.0, imu_grade="consumer", noise="white", seed=17))
    _, cfg, findings, _ = _check(run, **AUTO_OFFSET)
    d = findings[0].details
    assert d["offset_s"] == 0.0 and cfg["mounting"]["imu_time_offset_s"] == 0.0, (
        d
    )  # nothing applied
    assert abs(d["measured_s"]) <= 3.0 * d["sigma_s"] and abs(d["measured_s"]) < 0.5, d
    _check(run)  # and no error with the default 0


@pytest.mark.parametrize("scenario", SCENARIOS)
def test_small_clock_offset_is_left_alone(scenario, sims):
    """30 ms: within what never triggers anything (50 ms)."""
    run = sims(scenario)
    bad = _late_clock(run, 0.03)
    out, _, findings, _ = _check(bad)
    assert out is bad and findings == []


# --- 6. latitude and longitude -----------------------------------------------------------------------------


@pytest.mark.parametrize("how", ["swapped", "longitude-sign-lost"])
@pytest.mark.parametrize("scenario", SCENARIOS)
def test_mirrored_track_is_an_error(scenario, how, sims):
    run = sims(scenario)
    g = run.gnss
    bad = _fixes(run, g.lon, g.lat) if how == "swapped" else _fixes(run, g.lat, -g.lon)
    # Never repaired, whatever the policy: which of the readings is right is not known.
    for policy in ("apply", "refuse"):
        err = _error(bad, checks={"on_proof": policy})
        assert err.where == f"{RUN_DIR}/gnss.csv"
        assert (
            "mirror image" in err.problem and "swapped" in err.problem and "lat_deg" in err.problem
        )
        assert "cannot tell swapped latitude and longitude from a lost sign" in err.problem


@pytest.mark.parametrize("scenario", SCENARIOS)
def test_latlon_in_radians_from_a_csv_file(scenario, sims, tmp_path):
    """gnss.csv holding radians in its lat_deg, lon_deg columns, loaded by the CSV loader (which
    takes them for degrees): detected, and repaired to the true positions."""
    run = sims(scenario)
    g = run.gnss
    # write_csv_run writes degrees(lat): with lat = radians(true lat in rad) the file holds radians.
    in_radians = replace(run, gnss=replace(g, lat=np.radians(g.lat), lon=np.radians(g.lon)))
    folder = write_csv_run(in_radians, tmp_path / "rad")
    loaded = load_csv_run(folder, load_config())
    np.testing.assert_allclose(np.degrees(loaded.gnss.lat), g.lat, rtol=1e-12)  # as it arrives
    err = _error(loaded)
    assert (
        err.where == str(folder / "gnss.csv")
        and "radians" in err.problem
        and "180/pi" in err.problem
    )
    out, _, findings, texts = _check(loaded)
    assert [(f.check, f.action) for f in findings] == [("latlon", "repaired")]
    np.testing.assert_allclose(out.gnss.lat, g.lat, rtol=1e-12, atol=0)
    np.testing.assert_allclose(out.gnss.lon, g.lon, rtol=1e-12, atol=0)
    # The tangent plane moved with them: the repaired track is the true one, metre for metre.
    true_ned = run.origin.to_ned(g.lat, g.lon, g.h)
    np.testing.assert_allclose(
        out.origin.to_ned(out.gnss.lat, out.gnss.lon, out.gnss.h), true_ned - true_ned[0], atol=1e-3
    )
    np.testing.assert_allclose(out.truth.lat, run.truth.lat, rtol=1e-12)  # truth.csv was right
    assert "multiplied latitude and longitude by 180/pi" in findings[0].repaired and texts == []


def test_a_track_really_near_0_0_is_not_taken_for_radians():
    """A recording really made within 1.6 deg of latitude and 3.2 deg of longitude of (0, 0) (where
    radians read as degrees land): the IMU agrees with the track's accelerations as they are."""
    run = _as_csv(
        simulate(
            "car",
            120.0,
            imu_grade="consumer",
            noise="white",
            seed=SEED,
            origin_llh_deg=(0.5, 1.0, 0.0),
        )
    )
    assert np.all(np.abs(np.degrees(run.gnss.lat)) < 1.57) and np.all(
        np.abs(np.degrees(run.gnss.lon)) < 3.14
    )
    out, _, findings, _ = _check(run, **REPAIR)
    assert out is run and findings == []


# --- 7. mounting -------------------------------------------------------------------------------------------

MOUNTINGS = {
    "upside-down": np.diag([1.0, -1.0, -1.0]),
    "sideways": euler_to_dcm(np.pi / 2, 0.0, 0.0),
    "yawed-90": euler_to_dcm(0.0, 0.0, np.pi / 2),
}


@pytest.mark.parametrize("mounting", list(MOUNTINGS))
@pytest.mark.parametrize("scenario", SCENARIOS)
def test_mounting_error_names_the_line_that_fixes_it(scenario, mounting, sims):
    run = sims(scenario)
    bad = _rotated(run, MOUNTINGS[mounting])
    err = _error(bad)
    assert (
        err.where == f"{RUN_DIR}/imu.csv"
        and "not as [mounting] imu_to_body_rpy_deg = [0, 0, 0] says" in err.problem
    )
    rpy = json.loads(_value_after(err.problem, "set [mounting] imu_to_body_rpy_deg"))
    line = {"mounting": {"imu_to_body_rpy_deg": rpy}}
    fixed = replace(
        bad, imu=apply_mounting(bad.imu, load_config(overrides=line))
    )  # as a source loads it
    assert _max_angle_deg(fixed.imu.f_b, run.imu.f_b) < 1.0
    assert _max_angle_deg(fixed.imu.omega_ib_b, run.imu.omega_ib_b) < 1.0
    _, _, findings, _ = _check(fixed, **line)  # ... and it passes
    assert findings == []


@pytest.mark.parametrize("seed", range(6))
def test_short_run_with_outages_is_not_taken_for_a_yawed_imu(seed):
    """40 s with 5-s outages every 20 s leaves about one independent turn window: the yaw is
    undetermined, never "+-3 deg" off by 50 deg (it was, for 3 of these 6 draws)."""
    from gnssacc.sources.gnss_noise import apply_outages, parse_outages

    run = simulate("car", duration_s=40.0, imu_grade="industrial", noise="white", seed=seed)
    run = apply_outages(run, parse_outages(None, "20:5", run.duration_s))
    _, _, findings, _ = _check(_as_csv(run))
    assert [f for f in findings if f.check == "mounting"] == []


@pytest.mark.parametrize("mounting", list(MOUNTINGS))
@pytest.mark.parametrize("scenario", SCENARIOS)
def test_auto_mounting_restores_the_body_axes(scenario, mounting, sims):
    run = sims(scenario)
    bad = _rotated(run, MOUNTINGS[mounting])
    out, cfg, findings, texts = _check(bad, **AUTO_MOUNT)
    assert _max_angle_deg(out.imu.f_b, run.imu.f_b) < 1.0
    assert _max_angle_deg(out.imu.omega_ib_b, run.imu.omega_ib_b) < 1.0
    # The configuration returned holds the rotation applied: from the IMU as logged to the body.
    again = apply_mounting(
        bad.imu,
        load_config(
            overrides={
                "mounting": {"imu_to_body_rpy_deg": list(cfg["mounting"]["imu_to_body_rpy_deg"])}
            }
        ),
    )
    np.testing.assert_allclose(again.f_b, out.imu.f_b, atol=1e-9)
    assert [(f.check, f.action) for f in findings] == [("mounting", "applied")]
    assert "imu_to_body_rpy_deg = [" in findings[0].repaired and texts == []


def test_auto_mounting_of_an_oblique_imu(sims):
    """Turned 45 deg about the vertical: no right angle to snap to, the yaw comes from the turns."""
    run = sims("car")
    R = euler_to_dcm(0.0, 0.0, np.radians(45.0))
    bad = _rotated(run, R)
    err = _error(bad)
    rpy = json.loads(_value_after(err.problem, "set [mounting] imu_to_body_rpy_deg"))
    assert abs(rpy[2] + 45.0) < 5.0
    out, _, _, _ = _check(bad, **AUTO_MOUNT)
    assert _max_angle_deg(out.imu.f_b, run.imu.f_b) < 5.0


@pytest.mark.parametrize("scenario", SCENARIOS)
def test_one_gyro_axis_with_the_wrong_sign(scenario, sims):
    """The gyro's z axis negated: it turns against the fixes while the accelerometer agrees."""
    run = sims(scenario)
    err = _error(_imu(run, w=run.imu.omega_ib_b * np.array([1.0, 1.0, -1.0])))
    assert (
        err.where == f"{RUN_DIR}/imu.csv"
        and "wrong sign" in err.problem
        and "gx, gy, gz" in err.problem
    )


# --- 8. fixes and start ------------------------------------------------------------------------------------


@pytest.mark.parametrize("scenario", SCENARIOS)
def test_heights_not_in_metres(scenario, sims):
    """Heights in millimetres: a unit brings them onto a road, the estimator proves it (an error
    naming the column, repaired when allowed); a geocentric radius: no unit does, no ground
    vehicle drives there: refused."""
    run = sims(scenario)
    mm = _fixes(run, run.gnss.lat, run.gnss.lon, run.gnss.h * 1000.0)
    err = _error(mm)
    assert (
        err.where == f"{RUN_DIR}/gnss.csv" and "h_m" in err.problem and "millimetres" in err.problem
    )
    assert (
        f"{np.median(mm.gnss.h):.6g} m" in err.problem and "the estimator proves it" in err.problem
    )
    out, _, findings, _ = _check(mm)
    assert [(f.check, f.action) for f in findings] == [("heights", "repaired")]
    np.testing.assert_allclose(out.gnss.h, run.gnss.h, rtol=1e-12)
    radius = _fixes(run, run.gnss.lat, run.gnss.lon, run.gnss.h + 6378137.0)
    err = _error(radius, checks={"on_proof": "apply"})
    assert err.where == f"{RUN_DIR}/gnss.csv" and "h_m" in err.problem and "metres" in err.problem
    assert f"{np.median(radius.gnss.h):.6g} m" in err.problem


@pytest.mark.parametrize("scenario", SCENARIOS)
def test_only_two_fixes(scenario, sims):
    run = sims(scenario)
    err = _error(replace(run, gnss=run.gnss.select(np.arange(len(run.gnss)) < 2)))
    assert err.where == f"{RUN_DIR}/gnss.csv"
    assert (
        "2 GNSS fix(es) within the IMU data's time span" in err.problem
        and "at least 3" in err.problem
    )


def _init_at(run, north_m: float) -> InitialState:
    """The true start, moved ``north_m`` north."""
    tr = run.truth
    lat, lon, h = run.origin.to_llh(
        run.origin.to_ned(tr.lat[0], tr.lon[0], tr.h[0]) + np.array([north_m, 0.0, 0.0])
    )
    return InitialState(
        float(tr.t[0]),
        float(lat),
        float(lon),
        float(h),
        tr.v_n[0],
        tr.rpy[0],
        np.full(3, 1.0),
        np.full(3, 0.1),
        np.radians([1.0, 1.0, 2.0]),
    )


@pytest.mark.parametrize("scenario", SCENARIOS)
def test_initial_position_far_from_the_fixes(scenario, sims):
    run = sims(scenario)
    err = _error(replace(run, init=_init_at(run, 5000.0)))
    assert err.where == f"{RUN_DIR}/init.json" and "initial position" in err.problem
    km = float(re.search(r"is ([0-9.]+) km from the GNSS fix", err.problem).group(1))
    assert 4.9 < km < 5.1, err.problem
    _, _, findings, _ = _check(replace(run, init=_init_at(run, 2.0)))  # fix noise away: fine
    assert findings == []


# --- 9. configuration of the checks ------------------------------------------------------------------------


def test_skip_leaves_a_check_out(sims):
    run = sims("car")
    mm = _fixes(run, run.gnss.lat, run.gnss.lon, run.gnss.h * 1000.0)
    _error(mm)
    out, _, findings, _ = _check(mm, checks={"skip": "heights"})
    # The heights are used as they are; the truth (in metres) then disagrees with the fixes.
    assert out.gnss is mm.gnss and out.imu is mm.imu
    assert [(f.check, f.action) for f in findings] == [("truth", "not scored")] and not out.truth
    out, _, findings, _ = _check(mm, checks={"skip": "heights, truth"})
    assert out is mm and findings == []
    both = _rotated(mm, MOUNTINGS["upside-down"])
    assert "imu_to_body_rpy_deg" in _error(both, checks={"skip": "heights"}).problem
    _, _, findings, _ = _check(both, checks={"skip": " mounting,heights,truth "})
    assert findings == []
    # A skipped check repairs nothing either: the accelerometer stays in g, for what follows to see
    # (the fixes' scale against the IMU's: one view, a warning).
    in_g = _imu(run, f=run.imu.f_b / G0)
    out, _, _, texts = _check(in_g, checks={"skip": "accel_units", "repair": "auto"})
    assert out.imu.f_b is in_g.imu.f_b and not any("the accelerometer reads" in t for t in texts)
    ratio = float(
        re.search(r"the IMU measures ([0-9.]+) times the accelerations", " ".join(texts)).group(1)
    )
    assert ratio == pytest.approx(1.0 / G0, rel=0.2)


@pytest.mark.parametrize(
    "overrides, words",
    [
        ({"checks": {"skip": "heights, speeds"}}, ["[checks] skip", "speeds", "time_offset"]),
    ],
)
def test_bad_check_configuration(overrides, words, sims):
    err = _error(sims("car"), **overrides)
    assert err.where == "config"
    for w in words:
        assert w in err.problem, (w, err.problem)


def test_bad_repair_mode_is_refused_when_the_configuration_is_read(tmp_path):
    """Before any data are loaded, naming the file."""
    path = tmp_path / "c.toml"
    path.write_text('[checks]\nrepair = "yes"\n')
    with pytest.raises(InputError) as exc:
        load_config(path=path)
    assert exc.value.where == str(path)
    for w in ("[checks] repair", '"yes"', '"never"', '"auto"'):
        assert w in exc.value.problem, (w, exc.value.problem)


def test_every_check_name_can_be_skipped(sims):
    """All of them at once: the checks are bypassed even on a run that is wrong in every way."""
    run = sims("car")
    bad = _rotated(
        _imu(_fixes(run, run.gnss.lon, run.gnss.lat, run.gnss.h * 1000.0), f=run.imu.f_b / G0),
        MOUNTINGS["sideways"],
    )
    out, cfg, findings, texts = _check(bad, checks={"skip": ", ".join(CHECKS)})
    assert out is bad and findings == [] and texts == []


# --- 10. the command line ----------------------------------------------------------------------------------

FAST = ["--methods", "ekf", "--tune", "none", "--no-plots"]


def _cli(args, capsys):
    code = cli.main([str(a) for a in args] + FAST)
    return code, capsys.readouterr().err


def _metrics(out) -> dict:
    return json.loads((out / "metrics.json").read_text())


@pytest.fixture(scope="module")
def car_csv(tmp_path_factory):
    """A car run (industrial IMU) as a clean CSV run directory stamped in UNIX seconds (2024),
    and the metrics of a clean run."""
    root = tmp_path_factory.mktemp("cli")
    run = simulate(
        "car", 120.0, imu_grade="industrial", noise="white", seed=SEED, t_start_s=1709294400.0
    )
    clean = write_csv_run(run, root / "clean")
    assert cli.main(["run", str(clean), "--out", str(root / "o_clean"), *FAST]) == 0
    return run, _metrics(root / "o_clean")


def _auto_config(tmp_path, text):
    path = tmp_path / "auto.toml"
    path.write_text(text)
    return path


def _cli_out(args, capsys):
    """``(exit code, stdout, stderr)`` of a fast ``gnssacc run``."""
    code = cli.main([str(a) for a in args] + FAST)
    got = capsys.readouterr()
    return code, got.out, got.err


def _header(out: str) -> str:
    """The run's header line (the first line on stdout)."""
    return out.splitlines()[0]


def test_cli_accelerometer_in_g(car_csv, tmp_path, capsys):
    """Refused with --strict (one error line), repaired by default and stated on the header line
    and in metrics.json, with no warning."""
    run, clean = car_csv
    in_g = write_csv_run(_imu(run, f=run.imu.f_b / G0), tmp_path / "in_g")
    code, err = _cli(["run", in_g, "--out", tmp_path / "o_never", "--strict"], capsys)
    lines = [ln for ln in err.splitlines() if ln.startswith("gnssacc: error:")]
    assert code == 2 and len(lines) == 1 and "Traceback" not in err, err
    assert lines[0].startswith(f"gnssacc: error: {in_g / 'imu.csv'}: ") and "in g" in lines[0]
    assert not (tmp_path / "o_never").exists()
    code, out, err = _cli_out(["run", in_g, "--out", tmp_path / "o_auto"], capsys)
    assert code == 0 and "in g" not in err and "9.80665" not in err, err  # stated, not warned
    assert "corrected, as the estimator proves: multiplied the specific force by 9.80665" in (
        _header(out)
    )
    got = _metrics(tmp_path / "o_auto")
    assert [a["check"] for a in got["input_corrections"]["applied"]] == ["accel_units"]
    assert got["methods"]["ekf"]["prmse_m"] == pytest.approx(
        clean["methods"]["ekf"]["prmse_m"], rel=0.05
    )


def test_cli_upside_down_imu_is_mounted_by_default(car_csv, tmp_path, capsys):
    """Acceptance: a CSV run with its IMU upside down runs by default with the mounting applied
    and stated; its PRMSE within 5 % of the same run correctly mounted."""
    run, clean = car_csv
    bad = write_csv_run(_rotated(run, MOUNTINGS["upside-down"]), tmp_path / "bad")
    code, err = _cli(["run", bad, "--out", tmp_path / "o_never", "--strict"], capsys)
    assert (
        code == 2
        and "set [mounting] imu_to_body_rpy_deg = [180, 0, 0]" in err
        and "Traceback" not in err
    ), err
    code, out, err = _cli_out(["run", bad, "--out", tmp_path / "o_auto"], capsys)
    assert code == 0 and "imu_to_body_rpy_deg = [180, 0, 0] (log-likelihood +" in _header(out)
    got = _metrics(tmp_path / "o_auto")
    assert got["input_corrections"]["applied"][0]["correction"] == (
        "imu_to_body_rpy_deg = [180, 0, 0]"
    )
    assert got["methods"]["ekf"]["prmse_m"] == pytest.approx(
        clean["methods"]["ekf"]["prmse_m"], rel=0.05
    )


def _logged_late(run, offset_s):
    """A logger whose clock needs ``offset_s`` added to reach the GNSS clock: the IMU and the
    truth it stamps (a CSV run's truth.csv is on the IMU's clock)."""
    late = _late_clock(run, offset_s)
    return replace(late, truth=replace(run.truth, t=run.truth.t - offset_s))


def _utc_imu_run(car_csv, tmp_path, capsys):
    """The car's IMU and truth stamped on UTC (18 s behind the fixes' GPS time, in 2024): refused
    with --strict, the offset applied by default: the leap seconds exactly (with 3 m fixes the
    likelihood alone is tens of milliseconds off, which the truth on the IMU's clock would
    carry)."""
    run, _ = car_csv
    bad = write_csv_run(_logged_late(run, 18.0), tmp_path / "utc")
    code, err = _cli(["run", bad, "--out", tmp_path / "o_never", "--strict"], capsys)
    assert code == 2 and "Traceback" not in err, err
    assert abs(float(_value_after(err, "set [mounting] imu_time_offset_s")) - 18.0) <= 0.25, err
    code, out, err = _cli_out(["run", bad, "--out", tmp_path / "o_auto"], capsys)
    assert code == 0, err
    return out + err, _metrics(tmp_path / "o_auto")


def test_cli_imu_on_utc_is_put_on_the_gnss_clock_by_default(car_csv, tmp_path, capsys):
    text, got = _utc_imu_run(car_csv, tmp_path, capsys)
    measured = float(re.search(r"imu_time_offset_s = ([-+0-9.]+) \(the IMU", text).group(1))
    assert measured == 18.0, text
    (applied,) = got["input_corrections"]["applied"]
    assert applied["check"] == "time_offset" and "log-likelihood" in applied["evidence"]


def test_cli_imu_on_utc_is_scored_over_the_whole_run_with_its_truth(car_csv, tmp_path, capsys):
    text, got = _utc_imu_run(car_csv, tmp_path, capsys)
    _, clean = car_csv
    assert "truth covers only" not in text and "disagrees" not in text
    w = got["scored_window_s"]  # the truth moved with the IMU's clock: the whole run is scored
    assert w[1] - w[0] == pytest.approx(got["duration_s"], abs=0.02)
    assert got["coverage"]["ekf"]["fraction"] == pytest.approx(1.0)
    assert got["methods"]["ekf"]["prmse_m"] == pytest.approx(
        clean["methods"]["ekf"]["prmse_m"], rel=0.05
    )


@pytest.mark.parametrize("seed", [0, 7])
def test_no_clock_or_gyro_false_alarm_across_outages_on_a_slow_ugv(seed):
    # A slow UGV, 3 m fixes at 5 Hz, 20 s outages every 60 s: the quadratic fits bridged the
    # outages and invented accelerations, so the checks refused correct data ("IMU time stamps
    # run 16.7 s behind the GNSS clock" for seed 7, "the gyro's heading rate is 1.67 times the
    # GNSS course rate" for seed 0). Windows with a long stretch without fixes are not used.
    import gnssacc

    res = gnssacc.process(
        "sim:ugv-slow,imu=industrial,gnss_hz=5,duration=180",
        methods=["ekf"],
        noise="white",
        seed=seed,
        tune="none",
        outage_every="60:20",
    )
    assert res.metrics["methods"]["ekf"]["prmse_m"] < 5.0
