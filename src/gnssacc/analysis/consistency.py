r"""How far to trust each method's numbers: consistency figures and the warnings a user sees.

Figures (per method, all "per degree of freedom", 1 for a consistent estimator):

* **NIS** (EKF): the mean normalised innovation squared of each update kind (position,
  acceleration, zero velocity, zero rate), ``nu^T S^-1 nu / m``.
* **Normalised GNSS residual** (smoother, both estimates): the whitened residuals of the GNSS
  factors at the estimate, ``sum r^T Sigma^-1 r``, against their expectation for a consistent
  estimate, ``sum tr(Sigma^-1 C_r)`` with ``C_r = Sigma - J P J^T`` the covariance of the
  residual of a measurement the estimate includes (:func:`gnssacc.estimators.aids.gnss_position.residual_chi2`).
* **Innovation autocorrelation** (EKF): the lag-1 autocorrelation of the whitened position
  innovations. A correct model gives white innovations (~0); a slowly varying error the model
  misses (IMU noise set too low, time-correlated GNSS errors not modelled) makes it positive.
* **Fix residual ratio** (every method): ``sqrt(mean(r^T Sigma^-1 r) / 3)`` of the estimate
  against the fixes it was given, at the fix epochs. An estimate that uses the fixes lies closer
  to them than their noise (ratio < 1); an estimate independent of them and just as accurate
  would give ``sqrt(2)``: above that it is no better than the raw fixes it is fed.

Warnings (``gnssacc: warning: <method>: ...``) are raised when

* a NIS figure leaves the band :data:`NIS_BAND`, widened by three standard deviations of the
  mean of the updates actually made (``sqrt(2 / (m N))``, ``N`` the effective number of updates
  when the innovations are correlated in time, :func:`band`): outside it the stated 1-sigma is off
  by more than a factor ``sqrt(2)`` (too small above the band: the errors are larger than the
  method thinks; too large below it: it discards information);
* the innovations are correlated in time (lag-1 autocorrelation above :data:`ACF_MAX`);
* the position innovations have heavy tails: more of them beyond the chi-square bound of tail
  probability 0.1 % (:func:`gnssacc.estimators.aids.tail_bound`) than Gaussian errors would give
  (binomial tail probability below :data:`TAIL_ALARM`; white innovations only): the fixes carry
  outliers (multipath, jumps) that the noise model does not cover, and the stated uncertainty
  averages over them;
* the fix residual ratio exceeds :data:`FIX_RATIO_MAX`, or, with truth, the method's PRMSE at the
  raw fixes' epochs exceeds that of the fixes at the same epochs by more than :data:`WORSE_MARGIN`
  (like for like: fixes exist outside GNSS outages only, so a method's outage errors never count),
  or, within that margin, is no lower (the estimate adds nothing over the fixes);
* with truth, the position or attitude NEES per dof leaves its chi-square band
  (:func:`gnssacc.analysis.errorstats.nees_band`; the warning names the axes outside theirs);
* the configured white IMU noise is below what the IMU shows at rest by more than
  :data:`REST_FACTOR` (:func:`rest_noise_findings`). This needs no innovations, so it also catches
  an optimistic model whose innovations cannot show it (a tactical IMU beside 3 m fixes).

Zero-velocity and zero-rate updates are pseudo-measurements whose noise is a chosen bound, so only
a NIS above the band is reported for them (the vehicle moved, or the filter is overconfident).

The smoother's residuals cannot show a noise model that trusts the IMU too much (a smoothed
estimate fits the fixes either way). Every method of a run shares one noise model, so the model is
checked once, by the innovations of one EKF pass (:class:`ModelCheck`, made by
:func:`gnssacc.prepare.preparation.prepare`), and a failed check is reported for the smoothers too.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np

from ..core.distributions import binom_sf
from ..core.solution import NavSolution
from ..estimators.ekf import run_ekf
from ..estimators.aids import TAIL_P, tail_bound

#: Consistent band of a mean NIS per degree of freedom: the stated sigmas right within sqrt(2).
NIS_BAND = (0.5, 2.0)
#: Largest tolerated RMS of an estimate's residuals to its fixes, in units of their sigma.
FIX_RATIO_MAX = math.sqrt(2.0)
#: A method is reported as worse than the raw fixes (with truth) beyond this relative margin.
WORSE_MARGIN = 0.05
#: Largest tolerated lag-1 autocorrelation of the whitened innovations (and at least three
#: standard errors of it, 3 / sqrt(3 N)). On simulated runs with realistic IMUs the identified noise
#: gives at most 0.08 (60 runs); IMU noise set 10x too low gives up to 0.5 (attitude NEES 24-200
#: while the NIS is still 1.0-1.3); time-correlated fixes 0.75-0.9.
ACF_MAX = 0.1
#: A configured white-noise density smaller than the one measured at rest by more than this factor is
#: reported. The at-rest densities (Allan deviation of the stationary spans, :mod:`gnssacc.prepare.stationary`)
#: came out within 0.89-1.11x of the simulator's true values on 12 car-city / slow-UGV runs of every
#: grade with 95-110 s at rest; a factor 2 (4x in variance) is far outside that scatter.
REST_FACTOR = 2.0
#: Heavy tails are reported when the count beyond the bound has a binomial tail probability
#: below this under Gaussian errors (and at least 3 are beyond): a false alarm once in 10,000 runs.
TAIL_ALARM = 1e-4
#: What a warning can be about (:attr:`Consistency.flags`): the position NIS (the table's NIS
#: column), the comparison with the raw fixes, the position NEES, the attitude NEES, the GNSS
#: velocity's NIS (the table's ``NIS vel`` column), another update kind's NIS (``acc``,
#: ``zupt``, ``zaru``, ``nhc``, ``odo``) or the configured noise (``config``). The table marks
#: the columns it has; the others are marked nowhere.
COLUMNS = (
    "nis",
    "fixes",
    "nees",
    "nees_att",
    "vel",
    "acc",
    "zupt",
    "zaru",
    "nhc",
    "odo",
    "config",
)
#: Update kinds and their names in messages.
KIND_NAMES = {
    "pos": "position",
    "vel": "GNSS velocity",
    "acc": "acceleration",
    "zupt": "zero-velocity",
    "zaru": "zero-rate",
    "nhc": "non-holonomic",
    "odo": "wheel-odometry",
}
_DOF = {"pos": 3, "vel": 3, "acc": 3, "zupt": 3, "zaru": 3, "nhc": 2, "odo": 1}


def shown(value: float, *bounds: float, decimals: int = 2) -> list[str]:
    """``value`` and ``bounds`` as text, with as many decimals (from ``decimals``, at most 6) as it
    takes for the printed numbers to stand in the order the numbers do: a figure outside its band
    (or above its limit) reads visibly outside it ("1.94 outside [0.50, 1.90]", never "1.9 outside
    [0.5, 1.9]"), one inside reads inside."""
    for d in range(decimals, 7):
        texts = [f"{x:.{d}f}" for x in (value, *bounds)]
        r = [float(t) for t in texts]
        if all(
            (value < b) == (r[0] < rb) and (value > b) == (r[0] > rb)
            for b, rb in zip(bounds, r[1:], strict=True)
        ):
            break
    return texts


def outside(value: float, lo: float, hi: float, decimals: int = 2) -> str:
    """``"<value> outside [<lo>, <hi>]"`` with :func:`shown`'s digits."""
    v, a, b = shown(value, lo, hi, decimals=decimals)
    return f"{v} outside [{a}, {b}]"


def above(value: float, limit: float, decimals: int = 2) -> str:
    """``"<value> > <limit>"`` with :func:`shown`'s digits."""
    v, b = shown(value, limit, decimals=decimals)
    return f"{v} > {b}"


def acf_limit(n: int) -> float:
    """The largest lag-1 autocorrelation of ``n`` white innovations that is not reported
    (:func:`correlated`)."""
    return max(ACF_MAX, 3.0 / math.sqrt(3 * max(n, 1)))


def correlated(acf1: float | None, n: int) -> bool:
    """Whether ``n`` whitened innovations with lag-1 autocorrelation ``acf1`` are correlated in
    time: above :data:`ACF_MAX` and three standard errors of it."""
    return acf1 is not None and n > 10 and acf1 > acf_limit(n)


def heavy_tails(n_beyond: int, n: int, who: str, acf1: float | None = None) -> str | None:
    """The warning when ``n_beyond`` of ``n`` position innovations beyond ``tail_bound(3)`` are
    too many for Gaussian errors (``who``: whose innovations), else ``None``. Not for innovations
    correlated in time (``acf1``, :func:`correlated`): the count assumes independent ones, and the
    model is already reported as missing a slowly varying error, whose excursions it would count."""
    if n <= 0 or n_beyond < 3 or correlated(acf1, n):
        return None
    if binom_sf(n_beyond - 1, n, TAIL_P) >= TAIL_ALARM:
        return None
    return (
        f"the fixes carry outliers the noise model does not cover: {n_beyond} of {who} {n} position "
        f"innovations lie beyond the 0.1 % chi-square bound ({n * TAIL_P:.1f} expected for Gaussian errors); "
        f"the stated uncertainty averages over them, too large for most fixes and too small for these "
        f"([ekf] position_gate_nis = {tail_bound(3):.1f} makes the EKF reject them; the noise is still "
        f"identified from every fix)"
    )


@dataclass
class Consistency:
    """Consistency of one method's output.

    Attributes
    ----------
    method : str
    nis : dict
        Update kind -> mean NIS per dof (``None`` where the method made no such update).
    n : dict
        Update kind -> number of updates (factors) behind each figure.
    fix_ratio : float or None
        RMS of the normalised residuals to the fixes at the fix epochs (see the module docstring).
    acf1 : float or None
        Lag-1 autocorrelation of the whitened position innovations (EKF).
    warnings : list of str
    """

    method: str
    nis: dict
    n: dict
    fix_ratio: float | None
    acf1: float | None = None
    warnings: list = field(default_factory=list)
    flags: list = field(default_factory=list)

    def add(self, text: str, column: str) -> None:
        """Add a warning about the figure in table column ``column`` (:data:`COLUMNS`)."""
        self.warnings.append(text)
        self.flags.append(column)

    def to_dict(self) -> dict:
        return {
            "nis": self.nis,
            "n": self.n,
            "fix_residual_ratio": self.fix_ratio,
            "innovation_acf1": self.acf1,
            "warnings": self.warnings,
            "flags": self.flags,
        }


@dataclass
class ModelCheck:
    """The noise model against the recording: one EKF pass's position innovations.

    Attributes
    ----------
    nis : float or None
        Mean NIS per dof.
    acf1 : float or None
        Lag-1 autocorrelation of the whitened innovations.
    n : int
        Position updates.
    nis_zupt : float or None
        Mean NIS per dof of the zero-velocity updates: above the band, the model lets the velocity
        error grow more slowly than it does (the IMU noise is set too low).
    n_zupt : int
    rest : list of str
        The at-rest findings.
    n_beyond, n_rejected : int
        Position innovations beyond ``tail_bound(3)``, and fixes a position gate rejected.
    """

    nis: float | None
    acf1: float | None
    n: int
    nis_zupt: float | None = None
    n_zupt: int = 0
    rest: list = field(default_factory=list)
    n_beyond: int = 0
    n_rejected: int = 0

    @classmethod
    def from_stats(cls, stats: dict, rest: list | None = None) -> "ModelCheck":
        """From an EKF pass's ``stats`` and the at-rest findings (:func:`rest_noise_findings`)."""
        return cls(
            stats.get("nis_pos_mean"),
            stats.get("acf1_pos"),
            int(stats.get("n_pos_updates", 0) or 0),
            stats.get("nis_zupt_mean"),
            int(stats.get("n_zupt_updates", 0) or 0),
            list(rest or []),
            int(stats.get("n_pos_beyond", 0) or 0),
            int(stats.get("n_pos_rejected", 0) or 0),
        )

    def warnings(self) -> list[str]:
        """The model-level findings, worded for any method that uses the model."""
        out = []
        if self.nis is not None and self.n:
            lo, hi = band(self.n, acf1=self.acf1)
            if not lo <= self.nis <= hi:
                out.append(
                    f"the noise model does not fit this recording: the EKF's position NIS per dof "
                    f"with it is {outside(self.nis, lo, hi)}"
                )
        if correlated(self.acf1, self.n):
            out.append(
                f"the noise model misses a slowly varying error: the EKF's position innovations "
                f"with it are correlated in time (lag-1 autocorrelation "
                f"{above(self.acf1, acf_limit(self.n))}); IMU noise set too low or "
                f"time-correlated GNSS errors not modelled"
            )
        if self.nis_zupt is not None and self.n_zupt and self.nis_zupt > band(self.n_zupt)[1]:
            out.append(
                f"the noise model lets the velocity error grow too slowly: the EKF's zero-velocity "
                f"NIS per dof with it is {above(self.nis_zupt, band(self.n_zupt)[1])} while the "
                f"vehicle stands (IMU noise set too low)"
            )
        # Fixes a position gate rejected count as beyond the bound: the smoothers take them.
        tails = heavy_tails(
            self.n_beyond + self.n_rejected, self.n + self.n_rejected, "the EKF's", self.acf1
        )
        return out + ([tails] if tails else [])

    def to_dict(self) -> dict:
        return {
            "nis_pos": self.nis,
            "innovation_acf1": self.acf1,
            "n_pos_updates": self.n,
            "nis_zupt": self.nis_zupt,
            "n_zupt_updates": self.n_zupt,
            "at_rest": self.rest,
            "n_pos_beyond": self.n_beyond,
            "n_pos_rejected": self.n_rejected,
        }


def rest_noise_findings(measured: np.ndarray, configured: np.ndarray, seconds: float) -> list[str]:
    """Configured white IMU noise densities below those the IMU shows at rest.

    Parameters
    ----------
    measured : ndarray (6,)
        Densities read from the stationary spans, accelerometers [m/s/sqrt(s)] then gyros
        [rad/sqrt(s)], body axes (NaN where no span was long enough).
    configured : ndarray (6,)
        The model's densities, same order and units.
    seconds : float
        Stationary time behind ``measured`` [s].

    Returns
    -------
    list of str
        One finding per sensor (accelerometer, gyro) with a channel below ``measured / REST_FACTOR``,
        naming the configuration key and the value the recording shows.
    """
    out = []
    for name, key, sl, to_user, unit in (
        ("accelerometer", "accel_vrw_mps_rth", slice(0, 3), 60.0, "m/s/sqrt(h)"),
        ("gyro", "gyro_arw_deg_rth", slice(3, 6), 60.0 * 180.0 / math.pi, "deg/sqrt(h)"),
    ):
        m, c = np.asarray(measured[sl], float), np.asarray(configured[sl], float)
        ratio = np.where(np.isfinite(m) & (c > 0), m / np.where(c > 0, c, 1.0), np.nan)
        if np.any(ratio > REST_FACTOR):
            k = int(np.nanargmax(ratio))
            out.append(
                f"the configured {name} white noise ({key} = {c[k] * to_user:.3g} {unit} on axis "
                f"{'xyz'[k]}) is {ratio[k]:.1f}x below what the IMU shows at rest ({m[k] * to_user:.3g} "
                f"{unit}, from {seconds:.0f} s stationary): its stated uncertainty is too small"
            )
    return out


def band(n_updates: int, dof: int = 3, acf1: float | None = None) -> tuple[float, float]:
    """The consistent band for a mean NIS per dof over ``n_updates`` updates of ``dof`` each.

    ``acf1``: the lag-1 autocorrelation of the whitened innovations when known. Correlated
    innovations (a model that misses a slowly varying error) are worth fewer independent
    updates: their squares correlate by ``acf1^2``, which for an AR(1) sequence leaves
    ``n (1 - acf1^2) / (1 + acf1^2)`` (:func:`gnssacc.analysis.errorstats.effective_count`)."""
    r2 = 0.0 if acf1 is None or not math.isfinite(acf1) else min(max(acf1, 0.0), 0.999) ** 2
    n_eff = max(n_updates, 1) * (1.0 - r2) / (1.0 + r2)
    spread = 3.0 * math.sqrt(2.0 / (dof * max(n_eff, 1.0)))
    return min(NIS_BAND[0], 1.0 - spread), max(NIS_BAND[1], 1.0 + spread)


def fix_residual_ratio(run, sol: NavSolution, gm_sigma: np.ndarray | None = None) -> float | None:
    """RMS normalised residual of the solution's positions to the run's fixes (see module docstring).

    The solution is interpolated linearly to the fix epochs inside its span; antenna lever arms
    are not applied (the residual then includes the lever arm, which only makes it conservative).
    A fix's noise is its white sigma and, when modelled, the Gauss-Markov sigma ``gm_sigma``
    [m, N/E/D] (the estimate rightly does not follow that part).
    """
    g = run.gnss
    inside = (g.t >= sol.t[0]) & (g.t <= sol.t[-1]) if len(sol) > 1 else np.zeros(len(g), bool)
    if inside.sum() < 3:
        return None
    p_sol = run.origin.to_ned(sol.lat, sol.lon, sol.h)
    p_at = np.column_stack([np.interp(g.t[inside], sol.t, p_sol[:, i]) for i in range(3)])
    sigma = np.hypot(g.sigma_ned[inside], 0.0 if gm_sigma is None else gm_sigma)
    r = (p_at - run.origin.to_ned(g.lat[inside], g.lon[inside], g.h[inside])) / sigma
    return float(np.sqrt(np.mean(np.sum(r**2, axis=1)) / 3.0))


def check_model(prep) -> ModelCheck:
    """The prepared recording's final noise model against the recording: one EKF pass's
    innovations with it (the covariance propagated every ``[tune] cov_every`` samples, as the
    tuner's passes), and the at-rest findings (:func:`rest_noise_findings`).

    Parameters
    ----------
    prep : gnssacc.prepare.prepared.Prepared
    """
    cfg = prep.cfg
    check = run_ekf(
        prep.run,
        cfg,
        "ekf",
        init=prep.init,
        stationary=prep.stationary,
        quality=prep.quality,
        output_times=np.zeros(0),
        cov_every=int(cfg["tune"]["cov_every"]),
    )
    noise = prep.rest_noise
    rest = (
        rest_noise_findings(
            noise.white_density, np.sqrt(np.r_[cfg.accel_psd, cfg.gyro_psd]), noise.total_s
        )
        if noise is not None
        else []
    )
    return ModelCheck.from_stats(check.stats, rest)


def check_gm_model(
    prep, baseline: ModelCheck | None, ekf_gm: NavSolution | None = None
) -> ModelCheck:
    """The ``-gm`` methods' noise-model check (:attr:`gnssacc.prepare.prepared.Prepared.gauss_markov`):
    one EKF pass with the Gauss-Markov states, as :func:`check_model` checks the baselines' model;
    what the ``-gm`` methods' consistency is judged with (a smoother's own figures cannot show the
    model; the baselines' check is of the white model). ``ekf_gm``: the ``ekf-gm`` solution when
    the run has one, which is that pass (its outputs change nothing in the filter); the at-rest
    findings are the baseline's."""
    gm = prep.gauss_markov[0]
    check = ekf_gm or run_ekf(
        gm.run,
        gm.cfg,
        "ekf",
        init=gm.init,
        stationary=gm.stationary,
        quality=gm.quality,
        output_times=np.zeros(0),
    )
    return ModelCheck.from_stats(check.stats, baseline.rest if baseline is not None else [])


def assess(
    run,
    sol: NavSolution,
    prmse_m: float | None = None,
    gnss_prmse_m: float | None = None,
    model: ModelCheck | None = None,
    gm_sigma: np.ndarray | None = None,
    errors: dict | None = None,
    n_fixes: int | None = None,
    tuned: bool = False,
) -> Consistency:
    """Consistency figures and warnings of one solution.

    ``prmse_m`` / ``gnss_prmse_m``: with truth, the solution's and the raw fixes' PRMSE at the same
    ``n_fixes`` epochs (the fix epochs: :func:`gnssacc.analysis.errorstats.at_fixes`; never a method's
    score over its outages against the fixes', which exist outside them only); ``model``: the run's
    noise-model check, reported for methods whose own figures cannot show it; ``gm_sigma``: the
    modelled Gauss-Markov part of the fix errors [m]; ``errors``: the solution's
    :func:`gnssacc.analysis.errorstats.error_statistics`, for the NEES warnings. Each warning is
    flagged with the table column it is about (:attr:`Consistency.flags`). ``tuned``: the noise
    was identified from this recording (``--tune auto``), so a misfit is advised as the model's
    (what it lacks), never as something ``--tune auto`` would find."""
    st = sol.stats
    advice = (
        "the noise identified from this recording still misfits: the model lacks an error this "
        "recording has (see nis.png)"
        if tuned
        else "check the noise configuration (--tune auto identifies it from the recording)"
    )
    nis = {k: st.get(f"nis_{k}_mean") for k in _DOF}
    n = {k: int(st.get(f"n_{k}_updates", 0) or 0) for k in _DOF}
    c = Consistency(sol.method, nis, n, fix_residual_ratio(run, sol, gm_sigma), st.get("acf1_pos"))
    _nis_warnings(c, st, n, advice, tuned)
    _model_warnings(c, model)
    _fix_warnings(c, prmse_m, gnss_prmse_m, n_fixes)
    for text, column in nees_warnings(errors or {}):
        c.add(text, column)
    return c


def _nis_warnings(c: Consistency, st: dict, n: dict, advice: str, tuned: bool = False) -> None:
    """Warnings into ``c`` for each update kind's NIS outside its band, correlated position
    innovations and heavy tails (``st``: the solution's stats, ``n``: updates per kind;
    ``tuned``: the noise identified from the recording, the odometry's sigma inflated for its
    errors' correlation by the fixes' likelihood, so its one-step NIS lies below 1 by design)."""
    for kind, value in c.nis.items():
        if value is None or n[kind] == 0:
            continue
        lo, hi = band(n[kind], _DOF[kind], st.get(f"acf1_{kind}"))
        if kind in ("zupt", "zaru", "nhc") or (kind == "odo" and tuned):
            # pseudo-measurements: a conservative noise (the constraint's default) loses no trust;
            # a tuned odometry's white sigma states what the filter averages of correlated errors
            lo = 0.0
        if not lo <= value <= hi:
            what = (
                "its stated uncertainty is too small: its errors are larger than it thinks"
                if value > hi
                else "its stated uncertainty is too large: it discards information"
            )
            v, a, b = shown(value, lo, hi)
            c.add(
                f"{KIND_NAMES[kind]} NIS per dof {v}, outside the consistent band [{a}, {b}] "
                f"({n[kind]} updates): {what}; {advice}",
                "nis" if kind == "pos" else kind,
            )
    if correlated(c.acf1, n["pos"]):
        c.add(
            f"its position innovations are correlated in time (lag-1 autocorrelation "
            f"{above(c.acf1, acf_limit(n['pos']))}): the model misses a slowly varying error (IMU "
            f"noise set too low, or time-correlated GNSS errors not modelled), so its stated "
            f"uncertainty is not to be trusted",
            "nis",
        )
    tails = (
        heavy_tails(int(st.get("n_pos_beyond", 0) or 0), n["pos"], "the EKF's", c.acf1)
        if c.acf1 is not None
        else None
    )
    if tails:
        c.add(tails, "nis")


def _model_warnings(c: Consistency, model: ModelCheck | None) -> None:
    """The run's noise-model check into ``c``: its warnings for a method whose own figures cannot
    show them (not an EKF), and the rest for every method."""
    if model is not None and c.acf1 is None:  # not an EKF: its own figures cannot see the model
        for text in model.warnings():
            c.add(text, "nis")
    if model is not None:  # no method's own figures can see it
        for text in model.rest:
            c.add(text, "config")


def _fix_warnings(c: Consistency, prmse_m, gnss_prmse_m, n_fixes) -> None:
    """Warnings into ``c`` when the solution is no better than the raw fixes it is fed: by its
    residuals to them, or by its PRMSE [m] against the fixes' at the same ``n_fixes`` epochs."""
    if c.fix_ratio is not None and c.fix_ratio > FIX_RATIO_MAX:
        c.add(
            f"its positions are as far from the GNSS fixes as an independent estimate no better "
            f"than them would be (RMS normalised residual {above(c.fix_ratio, FIX_RATIO_MAX)}): "
            f"it does no better than the raw fixes it is fed",
            "fixes",
        )
    if (
        prmse_m is not None
        and gnss_prmse_m is not None
        and prmse_m > (1.0 + WORSE_MARGIN) * gnss_prmse_m
    ):
        p, g = shown(prmse_m, gnss_prmse_m)
        c.add(
            f"PRMSE {p} m at the {n_fixes} raw fix epochs is worse than the raw fixes' "
            f"{g} m at the same epochs (against the truth)",
            "fixes",
        )
    elif prmse_m is not None and gnss_prmse_m is not None and prmse_m >= gnss_prmse_m:
        p, g = shown(prmse_m, gnss_prmse_m)
        c.add(
            f"PRMSE {p} m at the {n_fixes} raw fix epochs is no better than the raw fixes' "
            f"{g} m at the same epochs (within {100 * WORSE_MARGIN:.0f} %): it adds nothing over "
            f"the fixes on this recording",
            "fixes",
        )


def nees_warnings(stats: dict) -> list[tuple[str, str]]:
    """One warning per NEES (position, attitude) of :func:`gnssacc.analysis.errorstats.error_statistics`
    outside its band, or with axes outside theirs, and the table column it is about (``nees``,
    ``nees_att``). The pooled figure is said to be outside only when it is; axes outside their own
    band are named with their figure and band, and which way each is off."""
    out = []
    for key, what, column in (
        ("nees_position", "position", "nees"),
        ("nees_attitude", "attitude", "nees_att"),
    ):
        n = stats.get(key)
        if not n or not (n["pooled_outside"] or n["outside"]):
            continue
        lo, hi = n["band"]
        axes = n["per_axis"]
        high = [a for a in n["outside"] if axes[a]["value"] > axes[a]["band"][1]]
        low = [a for a in n["outside"] if a not in high]
        if not high and not low:
            high, low = (["pooled"], []) if n["value"] > hi else ([], ["pooled"])
        says = (
            [f"{', '.join(high)}: errors larger than the stated sigma says"] if high else []
        ) + (
            [f"{', '.join(low)}: stated sigma larger than the errors (too cautious)"] if low else []
        )
        if n["pooled_outside"]:
            each = ", ".join(f"{a} {shown(v['value'], decimals=1)[0]}" for a, v in axes.items())
            v, a, b = shown(n["value"], lo, hi, decimals=1)
            head = (
                f"{what} NEES per dof against the truth {v}, outside its chi-square band "
                f"[{a}, {b}] (per axis {each})"
            )
        else:
            each = "; ".join(
                f"{a} {outside(axes[a]['value'], *axes[a]['band'], 1)}" for a in n["outside"]
            )
            v, a, b = shown(n["value"], lo, hi, decimals=1)
            head = (
                f"{what} NEES per dof against the truth: {each}, the axis's chi-square band (all "
                f"axes together {v}, inside [{a}, {b}])"
            )
        out.append((f"{head}; {'; '.join(says)}", column))
    return out
