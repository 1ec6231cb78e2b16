r"""Yaw at the start of a recording from a bank of hypotheses scored by innovation likelihood.

The start state (:func:`gnssacc.prepare.initialise.start_state`) fixes position, velocity and
roll/pitch; the yaw is unknown. ``[init] yaw_hypotheses`` = n filters start with yaws
``2 pi k / n`` and a 1-sigma of half the spacing, and run the EKF (position and stationary
updates) from the start.
Each hypothesis k accumulates the Gaussian log-likelihood of its innovations, ``L_k(t)``; with
equal prior weights its posterior probability is ``p_k = exp(L_k) / sum_j exp(L_j)``.

A wrong yaw makes the IMU's accelerations point the wrong way in n, so the position innovations
of that filter grow as soon as the vehicle accelerates or turns — including when it reverses:
the bank needs neither a forward-moving vehicle nor a speed threshold, and a reversing start
cannot produce a 180-degree heading. At low speed a filter started a few tens of degrees off
does not always converge (it can explain the small accelerations with an accelerometer bias), and
the likelihood then wavers between the two hypotheses either side of the truth. The decision is
therefore made in two levels: the *sector* of the best hypothesis (it and its two neighbours) is
found once its posterior mass reaches ``[init] yaw_confidence`` and stays there; then seven
hypotheses a quarter of the spacing apart, centred on the best, are scored over the same stretch,
and the most likely starts the estimators with a yaw sigma covering their posterior spread. The
horizon starts ``[init] yaw_horizon_s`` after the vehicle starts to move and doubles until the
sector is found or the run ends. When the data never tell (a vehicle that never accelerates or
turns), the best hypothesis is kept with the yaw sigma of a yaw uniform on the circle (104
deg), and the account says so; so does a recording in which the vehicle never moves (its yaw would
show only through the earth rate, gyrocompassing, which this bank does not attempt).
"""

from __future__ import annotations

from dataclasses import dataclass, replace

import numpy as np

from ..core.config import RunConfig
from ..core.parallel import KeptWorkers, side_by_side
from ..core.recording import InitialState, RecordedRun
from ..core.rotations import wrap_angle
from .filter_pass import FilterPass
from .initialise import StartState, hypothesis, start_state
from .tuning import without_aids

#: Update kinds whose likelihood scores a hypothesis.
_SCORED = ("pos", "vel", "zupt", "zaru")


@dataclass
class BankResult:
    """Outcome of the yaw bank.

    Attributes
    ----------
    init : InitialState
        The chosen start (its ``how`` says how yaw was found).
    yaws_deg : ndarray (n,)
        Starting yaw of each hypothesis [deg].
    posterior : ndarray (n,)
        Posterior probability of each at the horizon.
    confidence : float
        Posterior mass of the chosen sector (the best hypothesis and its neighbours).
    t_decided : float or None
        Time from which that mass stayed above the confidence level [s]; ``None``: undetermined.
    t_horizon : float
        End of the scored stretch [s].
    """

    init: InitialState
    yaws_deg: np.ndarray
    posterior: np.ndarray
    confidence: float
    t_decided: float | None
    t_horizon: float


@dataclass
class _Rows(KeptWorkers):
    """The hypotheses' passes of one bank: each hypothesis's cumulative log-likelihood on a time
    grid (:meth:`score`), the passes side by side in workers kept for every round of the bank (the
    first horizon, a doubled one, the refinement) and ended with the ``with`` block."""

    run: RecordedRun
    cfg: RunConfig
    stationary: object
    quality: object
    filter_pass: FilterPass

    def __post_init__(self):
        self.kept_for = self.row  # the workers :meth:`score` keeps, ended with the block

    def score(self, hyps, t_h: float):
        """Cumulative log-likelihood of each hypothesis on a common time grid up to ``t_h``; the
        hypotheses' passes side by side (:func:`gnssacc.core.parallel.side_by_side`: forked, each
        process holds the run; only a start and the likelihood rows travel), the same as one after
        the other."""
        grid = self.run.gnss.t[(self.run.gnss.t > hyps[0].t) & (self.run.gnss.t <= t_h)]
        rows = side_by_side(self.row, [(h, t_h, grid) for h in hyps], keep=True)
        return grid, np.array(rows).reshape(len(hyps), len(grid))

    def row(self, hyp: InitialState, t_h: float, grid: np.ndarray) -> np.ndarray:
        """One hypothesis's cumulative log-likelihood at ``grid`` [s] (its pass to ``t_h``)."""
        cfg = self.cfg
        sol = self.filter_pass(
            self.run,
            cfg,
            "ekf",
            init=hyp,
            stationary=self.stationary,
            quality=self.quality,
            output_times=np.zeros(0),
            record_innovations=True,
            t_stop=t_h,
            cov_every=int(cfg["tune"]["cov_every"]),
        )
        st = sol.stats
        t = np.concatenate([st[f"nis_{kind}_t"] for kind in _SCORED])
        ll = np.concatenate([st[f"loglik_{kind}_series"] for kind in _SCORED])
        order = np.argsort(t, kind="stable")
        cum = np.concatenate([[0.0], np.cumsum(ll[order])])
        return cum[np.searchsorted(t[order], grid, side="right")]


def _decide(L, yaws, level):
    """Best hypothesis at the horizon, the posterior over time of its sector (itself and its two
    neighbours in yaw) and the final posterior."""
    best = int(np.argmax(L[:, -1])) if L.shape[1] else 0
    spacing = 2.0 * np.pi / len(yaws) if len(yaws) > 1 else np.pi
    sector = np.abs(wrap_angle(yaws - yaws[best])) <= 1.01 * spacing
    P = np.exp(L - L.max(axis=0))
    P /= P.sum(axis=0)
    mass = P[sector].sum(axis=0) if L.shape[1] else np.zeros(0)
    stays = np.flatnonzero(mass < level)
    first_ok = 0 if stays.size == 0 else int(stays[-1]) + 1
    return best, mass, first_ok, (P[:, -1] if L.shape[1] else np.full(len(L), 1.0 / len(L)))


def _refine(rows: _Rows, start, yaw, spacing, t_h):
    """Seven hypotheses a quarter spacing apart around ``yaw``; the best one, with a yaw sigma
    covering the posterior spread (at least an eighth of the coarse spacing)."""
    step = spacing / 4.0
    yaws = yaw + step * np.arange(-3, 4)
    hyps = [hypothesis(rows.run, rows.cfg, start, y, step / 2.0) for y in yaws]
    _, L = rows.score(hyps, t_h)
    P = np.exp(L[:, -1] - L[:, -1].max()) if L.shape[1] else np.ones(len(hyps))
    P /= P.sum()
    best = int(np.argmax(P))
    sigma = max(step / 2.0, float(np.sqrt(np.sum(P * wrap_angle(yaws - yaws[best]) ** 2))))
    att = hyps[best].sigma_att_rad.copy()
    att[2] = sigma
    return replace(hyps[best], sigma_att_rad=att), float(P[best])


def select_yaw(
    run: RecordedRun,
    cfg: RunConfig,
    stationary=None,
    quality=None,
    start: StartState | None = None,
    *,
    filter_pass: FilterPass,
) -> BankResult:
    """Run the bank (see the module docstring) and return the chosen start.

    Parameters
    ----------
    run : RecordedRun
    cfg : RunConfig
        ``[init] yaw_hypotheses``, ``yaw_horizon_s``, ``yaw_confidence`` and the noise model.
    stationary : gnssacc.prepare.stationary.StationaryReport, optional
    quality : gnssacc.checks.quality.QualityReport, optional
    start : StartState, optional
        Computed with :func:`gnssacc.prepare.initialise.start_state` when omitted.
    filter_pass : FilterPass
        The EKF pass that scores the hypotheses (:func:`gnssacc.prepare.passes.filter_pass`).
    """
    # The hypotheses start far outside the vehicle aids' linearisation: the bank scores the IMU
    # and GNSS model alone (docs/estimators.md, "Its noise and the vehicle's axes").
    cfg = without_aids(cfg)
    c = cfg["init"]
    start = start or start_state(run, cfg, stationary)
    n = int(c["yaw_hypotheses"])
    yaws = 2.0 * np.pi * np.arange(n) / n
    hyps = [hypothesis(run, cfg, start, y, np.pi / n) for y in yaws]
    # Gates would let a wrong hypothesis skip the updates that expose it; so only the stationary
    # spans the fixes confirmed are scored: an IMU-still stretch inside an outage may be a smooth
    # cruise, whose zero-velocity updates, ungated, would condemn the right yaw (the one that knows
    # its velocity best) and crown a wrong one.
    ungated = cfg.with_values(
        {"zupt": {"gate_nis": 0.0}, "ekf": {"position_gate_nis": 0.0}}, "yaw bank"
    )
    if stationary is not None:
        stationary = replace(stationary, spans=[s for s in stationary.spans if s.gnss_checked])
    t_move = start.t if start.static is None else float(run.imu.t[start.static.stop - 1])
    horizon, level = float(c["yaw_horizon_s"]), float(c["yaw_confidence"])
    with _Rows(run, ungated, stationary, quality, filter_pass) as rows:
        while True:
            t_h = min(t_move + horizon, run.t_end)
            grid, L = rows.score(hyps, t_h)
            best, mass, first_ok, post = _decide(L, yaws, level)
            found = len(mass) > 0 and mass[-1] >= level
            if found or t_h >= run.t_end:
                break
            horizon *= 2.0
        if not found or t_move >= run.t_end - 1.0:
            # A vehicle that never moves shows its yaw only through the earth rate
            # (gyrocompassing), which takes a navigation-grade gyro and minutes of data: not
            # attempted here.
            return _undetermined(start, hyps, yaws, best, mass, post, t_h)
        init, p_fine = _refine(rows, start, yaws[best], 2.0 * np.pi / n, t_h)
    t_dec = float(grid[min(first_ok, len(grid) - 1)])
    how = (
        f"{start.how}; yaw from a bank of {n} hypotheses scored by innovation likelihood, "
        f"sector found {max(t_dec - t_move, 0.0):.0f} s after the vehicle started to move "
        f"(posterior {mass[-1]:.3f}), then refined at {np.degrees(2 * np.pi / n) / 4:.1f} deg: "
        f"{np.degrees(init.rpy[2]) % 360:.1f} deg +- {np.degrees(init.sigma_att_rad[2]):.1f}"
    )
    return BankResult(
        replace(init, how=how, yaw_evidence="bank"),
        np.degrees(yaws),
        post,
        float(mass[-1]),
        t_dec,
        t_h,
    )


#: 1-sigma of a yaw uniform on the circle, ``pi / sqrt(3)`` [rad] (104 deg).
UNIFORM_YAW_SIGMA = float(np.pi / np.sqrt(3.0))


def _undetermined(start, hyps, yaws, best, mass, post, t_h) -> BankResult:
    """Keep the best hypothesis with the yaw sigma of a yaw uniform on the circle (or the
    posterior's spread, were it wider): a bank that never reached its confidence has not told
    the yaw. A vehicle that never moved shows it the plainest: its hypotheses differ only in how
    each turns the same IMU noise, and the posterior they reach by chance (0.15-0.4 on one of
    twelve) would state a 30-deg sigma for a yaw 90-180 deg off."""
    chosen, n = hyps[best], len(yaws)
    spread = float(np.sqrt(np.sum(post * wrap_angle(yaws - yaws[best]) ** 2)))
    sigma = max(spread, float(chosen.sigma_att_rad[2]), UNIFORM_YAW_SIGMA)
    att = chosen.sigma_att_rad.copy()
    att[2] = sigma
    how = (
        f"{start.how}; yaw UNDETERMINED: a bank of {n} hypotheses could not tell them apart by the "
        f"end of the run (best {np.degrees(yaws[best]):.0f} deg, posterior {post[best]:.2f}; yaw "
        f"sigma set to {np.degrees(sigma):.0f} deg) - the vehicle never accelerated or turned "
        "enough"
    )
    conf = float(mass[-1]) if len(mass) else 0.0
    return BankResult(
        replace(chosen, sigma_att_rad=att, how=how, yaw_evidence="undetermined"),
        np.degrees(yaws),
        post,
        conf,
        None,
        t_h,
    )
