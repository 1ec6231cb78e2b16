r"""Per-state analysis: uncertainty histories, information per aiding, observability Gramians.

Four views of *which states the GNSS aiding makes observable, and when*:

1. :func:`sigma_history` -- the 1-sigma of every error state over time for any
   :class:`~gnssacc.core.solution.NavSolution` (EKF: filter covariance; smoother: the marginal
   covariance of each node), with :func:`state_errors` / :func:`consistency` setting the actual
   errors beside them where truth exists.
2. :func:`replay_ekf` + :func:`aiding_information` -- the EKF re-run with its own matrices
   (same propagation kernel, same ``H_p``, ``H_a``, ``R``); at each GNSS epoch the predicted
   covariance ``P-`` is updated with ``H_p`` alone and with ``H_p`` then ``H_a``, and the drop of
   each state's variance is recorded (per epoch and accumulated).
3. :func:`gramian` / :func:`sliding_gramian` -- the observability Gramian of the linearised
   error model over a window, its eigen-structure and a per-state *degree of observability*.
4. :mod:`gnssacc.analysis.motion` -- the motion context (stationary / straight / accelerating / turning)
   to read the above against.

Error-state order and units (estimate minus truth; :data:`STATE_NAMES`)::

    [dp N, E, D (m), dv N, E, D (m/s), roll, pitch, yaw (rad), b_a x, y, z (m/s^2), b_g x, y, z (rad/s)]

The filter's attitude error ``phi`` (n frame, ``R_est = (I + [phi x]) R``) is reported as
roll / pitch / yaw errors through :func:`gnssacc.core.rotations.euler_error_jacobian` everywhere in
this module, like ``NavSolution.sigma``.

Observability Gramian and degree of observability
-------------------------------------------------
Over a window of GNSS epochs ``k = k0 .. k1`` with transition matrices ``Phi(k, k0)`` of the
error model (the product of the EKF's per-IMU-sample ``I + F dt (+ (F dt)^2 / 2)``, F evaluated
at the *estimated* states along the trajectory) and measurement matrices ``H_k`` (``H_p``, or
``[H_p; H_a]``) with noise ``R_k``, the (stochastic, noise-weighted) observability Gramian is
the information about the error state at ``k0`` that the window's measurements carry:

    W = sum_k Phi(k, k0)^T H_k^T R_k^-1 H_k Phi(k, k0).

The states have different units, so W is normalised by a prior 1-sigma per state ``S`` (by
default the EKF's initial sigmas, a fixed scale that makes windows comparable):
``W_bar = S W S``. Its eigenvectors are the error directions (in prior-sigma units) and its
eigenvalues the information about each; near-zero eigenvalues are unobservable directions.

The **degree of observability** is that of Ham & Brown (1983): the eigen-structure of the error
covariance normalised by the prior, ``P_bar = S^-1 P S^-1``, whose eigenvalues lie in (0, 1]
(1 = no reduction, unobservable; -> 0 = perfectly observed). Here ``P`` is the covariance of the
state at ``k0`` given the prior and the window's measurements without process noise,
``P = (S^-2 + W)^-1``, so ``P_bar = (I + W_bar)^-1`` (same eigenvectors as ``W_bar``,
eigenvalues ``1 / (1 + lambda)``). Per state we report ``1 - P_bar[i, i]``: the fraction of the
prior variance of state ``i`` that the window's measurements remove (0 = unobservable, 1 =
fully observable). Reference: F. M. Ham and R. G. Brown, "Observability, eigenvalues, and
Kalman filtering", IEEE Trans. Aerospace and Electronic Systems, AES-19(2):269-273, 1983.
The Gramian itself: A. H. Jazwinski, *Stochastic Processes and Filtering Theory*, 1970 (the
information matrix of a linear system, Ch. 7).
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from ..checks.quality import QualityReport
from ..core.config import RunConfig
from ..core.display import (  # noqa: F401 (part of this module's API)
    DISPLAY_SCALE,
    DISPLAY_UNITS,
    STATE_NAMES,
)
from ..core.recording import RecordedRun
from ..core.rotations import dcm_to_euler, euler_error_jacobian
from ..core.solution import NavSolution
from ..core.states import ATT, N_NAV, NAV
from ..estimators.ekf import EkfObserver
from ..estimators.kalman import joseph_update
from ..prepare.passes import run_ekf
from .metrics import state_errors, truth_at  # noqa: F401 (state_errors: part of this module's API)

#: SI units per state (the display names and units are :mod:`gnssacc.core.display`'s).
STATE_UNITS = ("m",) * 3 + ("m/s",) * 3 + ("rad",) * 3 + ("m/s^2",) * 3 + ("rad/s",) * 3


def state_index(name: str) -> int:
    """Index of a state in :data:`STATE_NAMES`."""
    return STATE_NAMES.index(name)


# ---------------------------------------------------------------------------------------------
# 1. Uncertainty histories and actual errors
# ---------------------------------------------------------------------------------------------


@dataclass
class SigmaHistory:
    """1-sigma of every error state over time for one solution.

    Attributes
    ----------
    method : str
    t : ndarray, shape (K,)
        Epochs [s].
    sigma : ndarray, shape (K, 15)
        1-sigma per state in SI units, columns :data:`STATE_NAMES`.
    """

    method: str
    t: np.ndarray
    sigma: np.ndarray

    def __getitem__(self, name: str) -> np.ndarray:
        return self.sigma[:, state_index(name)]

    def as_dict(self, display_units: bool = False) -> dict[str, np.ndarray]:
        """``{"t": t, name: sigma, ...}``, optionally in :data:`DISPLAY_UNITS`."""
        s = self.sigma * DISPLAY_SCALE if display_units else self.sigma
        return {"t": self.t, **{n: s[:, i] for i, n in enumerate(STATE_NAMES)}}

    def reduction(self) -> np.ndarray:
        """Final over initial sigma per state (< 1: the state's uncertainty shrank)."""
        return self.sigma[-1] / self.sigma[0]


def sigma_history(sol: NavSolution) -> SigmaHistory:
    """Per-state 1-sigma history of a solution (filter covariance or smoother marginals)."""
    return SigmaHistory(sol.method, np.asarray(sol.t, float), np.asarray(sol.sigma, float))


def sigma_histories(sols: dict[str, NavSolution]) -> dict[str, SigmaHistory]:
    """:func:`sigma_history` for each solution of a ``{method: NavSolution}`` dict."""
    return {m: sigma_history(s) for m, s in sols.items()}


@dataclass
class Consistency:
    """Actual errors against predicted sigmas, per state.

    Attributes
    ----------
    method : str
    rms_error : ndarray, shape (15,)
        RMS of the actual error [SI]; NaN without truth for the state.
    rms_sigma : ndarray, shape (15,)
        RMS of the predicted 1-sigma over the same epochs [SI].
    within_1sigma, within_3sigma : ndarray, shape (15,)
        Share of epochs with ``|error| <= 1 sigma`` (0.683 for a consistent Gaussian estimate)
        and ``<= 3 sigma`` (0.997).
    nees : ndarray, shape (15,)
        Mean normalised error squared ``mean(e^2 / sigma^2)`` per state (1 if consistent).
    n : ndarray of int, shape (15,)
        Epochs scored per state.
    """

    method: str
    rms_error: np.ndarray
    rms_sigma: np.ndarray
    within_1sigma: np.ndarray
    within_3sigma: np.ndarray
    nees: np.ndarray
    n: np.ndarray

    def rows(self, display_units: bool = True) -> list[dict]:
        """One dict per state with truth (for a table)."""
        k = DISPLAY_SCALE if display_units else np.ones(N_NAV)
        units = DISPLAY_UNITS if display_units else STATE_UNITS
        return [
            {
                "state": STATE_NAMES[i],
                "unit": units[i],
                "rms_error": self.rms_error[i] * k[i],
                "rms_sigma": self.rms_sigma[i] * k[i],
                "within_1sigma": self.within_1sigma[i],
                "within_3sigma": self.within_3sigma[i],
                "nees": self.nees[i],
            }
            for i in range(N_NAV)
            if self.n[i] > 0
        ]


def consistency(run: RecordedRun, sol: NavSolution, t_min: float | None = None) -> Consistency:
    """Per-state consistency of a solution's sigmas with its actual errors.

    Parameters
    ----------
    run, sol
    t_min : float, optional
        Score only epochs at or after this time [s] (e.g. to skip the initial transient).
    """
    err = state_errors(run, sol)
    sig = np.asarray(sol.sigma, float)
    if t_min is not None:
        keep = sol.t >= t_min
        err, sig = err[keep], sig[keep]
    ok = np.isfinite(err) & (sig > 0)
    n = ok.sum(axis=0)
    out = {k: np.full(N_NAV, np.nan) for k in ("rms", "rms_s", "w1", "w3", "nees")}
    for i in range(N_NAV):
        if n[i] == 0:
            continue
        e, s = err[ok[:, i], i], sig[ok[:, i], i]
        out["rms"][i] = np.sqrt(np.mean(e**2))
        out["rms_s"][i] = np.sqrt(np.mean(s**2))
        out["w1"][i] = np.mean(np.abs(e) <= s)
        out["w3"][i] = np.mean(np.abs(e) <= 3 * s)
        out["nees"][i] = np.mean((e / s) ** 2)
    return Consistency(sol.method, out["rms"], out["rms_s"], out["w1"], out["w3"], out["nees"], n)


# ---------------------------------------------------------------------------------------------
# 2. Replay of the EKF with its own matrices
# ---------------------------------------------------------------------------------------------


@dataclass
class GnssEpoch:
    """What the EKF had at one GNSS epoch (all matrices in the filter's error state, phi in n).

    Attributes
    ----------
    t : float
    P_minus : ndarray (15, 15)
        Predicted covariance before any update.
    P_plus : ndarray (15, 15)
        Covariance after the updates the replayed method applied.
    H_p, R_p : ndarray (3, 15), (3, 3)
        Position update (as in the EKF, lever-arm term included).
    H_a, R_a : ndarray (3, 15), (3, 3) or None
        Acceleration update, whenever the LS window had a measurement (also for method
        ``ekf``, for the counterfactual), evaluated at the state after the position update.
    J : ndarray (3, 3)
        Euler-error Jacobian at the predicted state (``d_euler = J phi``).
    Phi : ndarray (15, 15) or None
        Transition of the error state from the previous epoch's post-update time to this
        epoch (``with_phi=True``); for the first epoch, from the filter start.
    pos_used, acc_used : bool
        Whether the replayed filter applied each update (gate, suspect IMU, method).
    """

    t: float
    P_minus: np.ndarray
    P_plus: np.ndarray
    H_p: np.ndarray
    R_p: np.ndarray
    H_a: np.ndarray | None
    R_a: np.ndarray | None
    J: np.ndarray
    Phi: np.ndarray | None
    pos_used: bool
    acc_used: bool


@dataclass
class EkfReplay:
    """Result of :func:`replay_ekf`.

    Attributes
    ----------
    method : str
    epochs : list of GnssEpoch
    P0 : ndarray (15, 15)
        Initial covariance (phi in n).
    J0 : ndarray (3, 3)
        Euler-error Jacobian at the initial state.
    t0 : float
        Filter start [s].
    """

    method: str
    epochs: list[GnssEpoch]
    P0: np.ndarray
    J0: np.ndarray
    t0: float
    stats: dict = field(default_factory=dict)

    @property
    def t(self) -> np.ndarray:
        return np.array([e.t for e in self.epochs])


def _cov_update(P: np.ndarray, H: np.ndarray, R: np.ndarray) -> np.ndarray:
    """Joseph-form covariance update with the optimal gain (:func:`gnssacc.estimators.kalman.joseph_update`)."""
    P = P.copy()
    joseph_update(P, H, R, np.zeros(len(H)), 0.0, -1)
    return P


def _euler_T(J: np.ndarray) -> np.ndarray:
    """Map from the reported error state (Euler angles) to the filter's (phi): ``dx_phi = T dx_euler``."""
    T = np.eye(N_NAV)
    T[ATT, ATT] = np.linalg.inv(J)
    return T


def _euler_var(P: np.ndarray, J: np.ndarray) -> np.ndarray:
    """Diagonal of P's 15 reported states (a filter with the three Gauss-Markov GNSS error states
    has 18; those come after them and are left out), the attitude block mapped to Euler-angle errors."""
    d = np.diag(P)[NAV].copy()
    d[ATT] = np.diag(J @ P[ATT, ATT] @ J.T)
    return np.maximum(d, 0.0)


class EpochCollector(EkfObserver):
    """Keeps the filter's matrices at every GNSS epoch (the observer of one :func:`run_ekf` pass:
    give it to ``run_ekf(..., observer=...)``, or to :func:`gnssacc.pipeline.compare` by method,
    then :meth:`replay` makes the :class:`EkfReplay`)."""

    def __init__(self, with_phi: bool):
        self.with_phi = with_phi
        self.epochs: list[GnssEpoch] = []
        self._cur: dict = {}
        self.P0 = self.init = None

    def start(self, setup):
        self.P0, self.init = setup.state.P.copy(), setup.init
        setup.prop.with_phi = self.with_phi
        setup.prop.reset_phi()

    def before(self, t, kind, s, prop):
        if kind == "gnss":
            self._cur = {
                "t": float(t),
                "P_minus": s.P.copy(),
                "J": euler_error_jacobian(*_rpy(s.R_nb)),
                "Phi": prop.Phi.copy() if self.with_phi else None,
                "H_a": None,
                "R_a": None,
                "acc_used": False,
            }

    def update(self, t, m, nis, used, s):
        if m.kind == "pos":
            self._cur.update(H_p=m.H, R_p=m.R, pos_used=used)
        elif m.kind == "acc":
            self._cur.update(H_a=m.H, R_a=m.R, acc_used=used)

    def replay(self, method: str, sol) -> EkfReplay:
        """The :class:`EkfReplay` of the pass this collector watched (``sol``: its solution)."""
        return EkfReplay(
            method,
            self.epochs,
            self.P0,
            euler_error_jacobian(*self.init.rpy),
            float(self.init.t),
            {"accel_window_resets": sol.stats["accel_window_resets"]},
        )

    def after(self, t, kind, s, prop):
        if kind == "gnss":
            c = self._cur
            self.epochs.append(
                GnssEpoch(
                    c["t"],
                    c["P_minus"],
                    s.P.copy(),
                    c["H_p"],
                    c["R_p"],
                    c["H_a"],
                    c["R_a"],
                    c["J"],
                    c["Phi"],
                    c["pos_used"],
                    c["acc_used"],
                )
            )
            prop.reset_phi()


def replay_ekf(
    run: RecordedRun,
    cfg: RunConfig,
    method: str = "ekf",
    *,
    with_phi: bool = False,
    quality: QualityReport | None = None,
    t_end: float | None = None,
    init=None,
    stationary=None,
) -> EkfReplay:
    """Run :func:`gnssacc.estimators.ekf.run_ekf` once and keep its matrices at every GNSS epoch.

    This is the filter's own pass (an :class:`gnssacc.estimators.ekf.EkfObserver` watches it), so the
    trajectory and covariances are the filter's; for ``ekf`` the acceleration update is also
    evaluated, not applied, for the counterfactual.

    Parameters
    ----------
    run : RecordedRun
    cfg : RunConfig
    method : {"ekf", "ekf-acc"}
        Which filter to run (which updates are applied to the trajectory).
    with_phi : bool
        Also accumulate the error-state transition matrix between GNSS epochs (in the
        propagation kernel, one 15 x 15 product per IMU sample).
    quality : QualityReport, optional
    t_end : float, optional
        Stop after the last GNSS epoch at or before this time [s].
    init : InitialState, optional
        Start (default: the run's or self-initialisation, as ``run_ekf``).
    stationary : gnssacc.prepare.stationary.StationaryReport, optional
        Stationary spans (their updates are applied, and fold into ``P_minus``).

    Returns
    -------
    EkfReplay
    """
    if method not in ("ekf", "ekf-acc"):
        raise ValueError(f"replay_ekf replays 'ekf' or 'ekf-acc', not {method!r}")
    c = EpochCollector(with_phi)
    sol = run_ekf(
        run,
        cfg,
        method,
        output_times=np.zeros(0),
        quality=quality,
        init=init,
        stationary=stationary,
        observer=c,
        t_stop=t_end,
    )
    return c.replay(method, sol)


def _rpy(R: np.ndarray) -> np.ndarray:
    return np.array(dcm_to_euler(R))


# ---------------------------------------------------------------------------------------------
# Information contributed by each aiding
# ---------------------------------------------------------------------------------------------


@dataclass
class AidingInformation:
    """Variance reduction by the position update alone and by position + acceleration.

    All variances are of the reported states (attitude as Euler-angle errors), SI units squared,
    one row per GNSS epoch, all computed from the same predicted covariance ``P-``.

    Attributes
    ----------
    t : ndarray (n,)
    var_prior : ndarray (n, 15)
        Diagonal of ``P-``.
    var_pos : ndarray (n, 15)
        After the position update alone.
    var_pos_acc : ndarray (n, 15)
        After the position then the acceleration update (= ``var_pos`` where no acceleration
        measurement existed).
    has_acc : ndarray of bool (n,)
    """

    method: str
    t: np.ndarray
    var_prior: np.ndarray
    var_pos: np.ndarray
    var_pos_acc: np.ndarray
    has_acc: np.ndarray

    @property
    def drop_pos(self) -> np.ndarray:
        """Variance removed by the position update, per epoch (n, 15)."""
        return self.var_prior - self.var_pos

    @property
    def drop_pos_acc(self) -> np.ndarray:
        """Variance removed by position + acceleration, per epoch (n, 15)."""
        return self.var_prior - self.var_pos_acc

    @property
    def drop_acc_extra(self) -> np.ndarray:
        """Additional variance removed by the acceleration update after the position update (n, 15)."""
        return self.var_pos - self.var_pos_acc

    def cumulative(self) -> dict[str, np.ndarray]:
        """Accumulated variance drops ``{"pos": (n, 15), "pos_acc": (n, 15)}``."""
        return {
            "pos": np.cumsum(self.drop_pos, axis=0),
            "pos_acc": np.cumsum(self.drop_pos_acc, axis=0),
        }

    def relative(self) -> dict[str, np.ndarray]:
        """Fraction of the predicted variance removed per epoch, ``{"pos": ..., "pos_acc": ...}`` (n, 15)."""
        with np.errstate(invalid="ignore", divide="ignore"):
            return {
                "pos": 1.0 - self.var_pos / self.var_prior,
                "pos_acc": 1.0 - self.var_pos_acc / self.var_prior,
            }

    def summary(self) -> dict[str, dict[str, float]]:
        """Per state: mean fraction of the predicted variance removed by each aiding (epochs with acceleration)."""
        rel = self.relative()
        m = self.has_acc
        return {
            n: {
                "pos": float(np.nanmean(rel["pos"][m, i])),
                "pos_acc": float(np.nanmean(rel["pos_acc"][m, i])),
            }
            for i, n in enumerate(STATE_NAMES)
        }


def aiding_information(replay: EkfReplay) -> AidingInformation:
    """Per-epoch variance drops of the position update alone vs position + acceleration.

    At each GNSS epoch of the replayed filter, ``P-`` is updated (Joseph form, the EKF's
    ``H_p``, ``R_p``) and then with ``H_a`` and the LS window's covariance ``R_a`` (or the
    configured fixed sigma), exactly the sequence the ``ekf-acc`` filter applies. The filter
    trajectory itself is that of ``replay.method``.
    """
    n = len(replay.epochs)
    vp, v1, v2 = np.empty((n, N_NAV)), np.empty((n, N_NAV)), np.empty((n, N_NAV))
    has = np.zeros(n, bool)
    for j, e in enumerate(replay.epochs):
        P1 = _cov_update(e.P_minus, e.H_p, e.R_p)
        vp[j], v1[j] = _euler_var(e.P_minus, e.J), _euler_var(P1, e.J)
        if e.H_a is not None:
            v2[j] = _euler_var(_cov_update(P1, e.H_a, e.R_a), e.J)
            has[j] = True
        else:
            v2[j] = v1[j]
    return AidingInformation(replay.method, replay.t, vp, v1, v2, has)


# ---------------------------------------------------------------------------------------------
# 3. Observability Gramian
# ---------------------------------------------------------------------------------------------


@dataclass
class Gramian:
    """Observability Gramian of one window and its derived quantities (reported state order).

    Attributes
    ----------
    t0, t1 : float
        First and last GNSS epoch of the window [s].
    aiding : str
        ``"pos"`` or ``"pos+acc"``.
    W : ndarray (15, 15)
        Gramian in SI units (information about the state at ``t0``; attitude as Euler errors).
    scale : ndarray (15,)
        Prior 1-sigma ``S`` used to normalise.
    W_bar : ndarray (15, 15)
        ``S W S`` (dimensionless).
    eigvals : ndarray (15,)
        Eigenvalues of ``W_bar``, ascending.
    eigvecs : ndarray (15, 15)
        Matching unit eigenvectors (columns), in prior-sigma units.
    degree : ndarray (15,)
        Ham & Brown degree of observability per state, ``1 - [(I + W_bar)^-1]_ii`` in [0, 1].
    n_pos, n_acc : int
        Measurements in the window.
    """

    t0: float
    t1: float
    aiding: str
    W: np.ndarray
    scale: np.ndarray
    W_bar: np.ndarray
    eigvals: np.ndarray
    eigvecs: np.ndarray
    degree: np.ndarray
    n_pos: int
    n_acc: int

    @property
    def normalised_covariance(self) -> np.ndarray:
        """Ham & Brown's normalised covariance ``(I + W_bar)^-1``."""
        return np.linalg.inv(np.eye(N_NAV) + self.W_bar)

    def degree_of(self, name: str) -> float:
        return float(self.degree[state_index(name)])

    def weakest(self, n: int = 4, top: int = 4) -> list[dict]:
        """The ``n`` least observable directions: eigenvalue, Ham & Brown eigenvalue ``1/(1+lambda)``
        and the ``top`` largest components ``{state: weight}`` of the unit eigenvector."""
        out = []
        for j in range(n):
            v = self.eigvecs[:, j]
            idx = np.argsort(-np.abs(v))[:top]
            out.append(
                {
                    "eigval": float(self.eigvals[j]),
                    "P_bar_eig": float(1.0 / (1.0 + max(self.eigvals[j], 0.0))),
                    "components": {STATE_NAMES[i]: float(v[i]) for i in idx},
                }
            )
        return out

    def information(self, direction: np.ndarray) -> float:
        """Normalised information about a direction: ``d^T W_bar d`` for the direction (SI units,
        reported order) expressed in prior-sigma units and scaled to unit length (an eigenvalue
        of ``W_bar`` when the direction is an eigenvector; ~0 = unobservable)."""
        d = np.asarray(direction, float) / self.scale
        d = d / np.linalg.norm(d)
        return float(d @ self.W_bar @ d)

    def subspace_projection(self, direction: np.ndarray, max_eigval: float) -> float:
        """Norm of the projection of a direction (SI units, reported order) onto the span of the
        eigenvectors with eigenvalue ``<= max_eigval`` (1 = the direction is in that weakly
        observable subspace)."""
        d = np.asarray(direction, float) / self.scale
        d = d / np.linalg.norm(d)
        V = self.eigvecs[:, self.eigvals <= max_eigval]
        return float(np.linalg.norm(V.T @ d))


def prior_scale(replay: EkfReplay) -> np.ndarray:
    """The EKF's initial 1-sigma per reported state (attitude as Euler errors) [SI]."""
    return np.sqrt(_euler_var(replay.P0, replay.J0))


def gramian(
    replay: EkfReplay, t0: float, t1: float, aiding: str = "pos", scale: np.ndarray | None = None
) -> Gramian:
    """Observability Gramian over the GNSS epochs in ``[t0, t1]`` (see the module docstring).

    Parameters
    ----------
    replay : EkfReplay
        From ``replay_ekf(..., with_phi=True)``.
    t0, t1 : float
        Window [s].
    aiding : {"pos", "pos+acc"}
        ``H = H_p`` or ``[H_p; H_a]`` (epochs without an acceleration measurement contribute
        ``H_p`` only).
    scale : ndarray (15,), optional
        Prior 1-sigma for the normalisation; default :func:`prior_scale`.
    """
    if aiding not in ("pos", "pos+acc"):
        raise ValueError("aiding must be 'pos' or 'pos+acc'")
    eps = [e for e in replay.epochs if t0 <= e.t <= t1]
    if not eps:
        raise ValueError(f"no GNSS epoch in [{t0}, {t1}]")
    if eps[0].Phi is None:
        raise ValueError(
            "the replay has no transition matrices: use replay_ekf(..., with_phi=True)"
        )
    # Reference: the state just before the first epoch's update, attitude as Euler errors there.
    T0 = _euler_T(eps[0].J)
    W = np.zeros((N_NAV, N_NAV))
    Phi = np.eye(N_NAV)
    n_pos = n_acc = 0
    for j, e in enumerate(eps):
        if j > 0:
            Phi = e.Phi @ Phi
        HPhi = [(e.H_p, e.R_p)] if e.pos_used else []
        if aiding == "pos+acc" and e.H_a is not None:
            HPhi.append((e.H_a, e.R_a))
        for H, R in HPhi:
            M = H @ Phi @ T0
            W += M.T @ np.linalg.solve(R, M)
        n_pos += int(e.pos_used)
        n_acc += int(aiding == "pos+acc" and e.H_a is not None)
    W = 0.5 * (W + W.T)
    S = prior_scale(replay) if scale is None else np.asarray(scale, float)
    W_bar = S[:, None] * W * S[None, :]
    lam, V = np.linalg.eigh(W_bar)
    degree = 1.0 - np.diag(np.linalg.inv(np.eye(N_NAV) + W_bar))
    return Gramian(
        eps[0].t, eps[-1].t, aiding, W, S, W_bar, lam, V, np.clip(degree, 0.0, 1.0), n_pos, n_acc
    )


@dataclass
class SlidingGramian:
    """Degree of observability over sliding windows.

    Attributes
    ----------
    t : ndarray (n,)
        Window centres [s].
    degree : ndarray (n, 15)
    min_eigval : ndarray (n,)
        Smallest eigenvalue of ``W_bar`` per window.
    n_weak : ndarray of int (n,)
        Eigenvalues of ``W_bar`` below 1 (directions whose prior variance the window does not
        even halve).
    """

    aiding: str
    window_s: float
    t: np.ndarray
    degree: np.ndarray
    min_eigval: np.ndarray
    n_weak: np.ndarray

    def __getitem__(self, name: str) -> np.ndarray:
        return self.degree[:, state_index(name)]


def sliding_gramian(
    replay: EkfReplay,
    window_s: float,
    step_s: float | None = None,
    aiding: str = "pos",
    scale: np.ndarray | None = None,
) -> SlidingGramian:
    """:func:`gramian` over windows of ``window_s`` seconds every ``step_s`` (default ``window_s / 2``)."""
    t = replay.t
    step = window_s / 2.0 if step_s is None else step_s
    starts = np.arange(t[0], t[-1] - window_s + 1e-9, step)
    cen, deg, mins, weak = [], [], [], []
    for a in starts:
        g = gramian(replay, a, a + window_s, aiding, scale)
        cen.append(a + window_s / 2.0)
        deg.append(g.degree)
        mins.append(g.eigvals[0])
        weak.append(int(np.sum(g.eigvals < 1.0)))
    return SlidingGramian(
        aiding,
        float(window_s),
        np.array(cen),
        np.array(deg).reshape(-1, N_NAV),
        np.array(mins),
        np.array(weak, int),
    )
