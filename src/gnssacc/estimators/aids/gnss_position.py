r"""GNSS position: the antenna's fix, in the EKF and the smoother.

Measurement
-----------
The fix is the antenna position plus, when modelled (``[gnss] gm_sigma_m > 0``), a first-order
Gauss-Markov error ``x_g`` (the ``gnss_error`` states, :mod:`gnssacc.estimators.layout`) plus
white noise of the stated sigma times ``[gnss] sigma_scale``
(:meth:`gnssacc.estimators.settings.GnssModel.fixes`; with the stated NED correlations when the
source has them). EKF: ``dz = p_ant,est (+ x_g) - p_fix`` in metres NED,
``H = [I, 0, -[(R l_b) x], 0, 0 (, I)]`` (``l_b`` the lever arm). Smoother: ``GPSFactor`` (or
``GPSFactorArm``) on the node's pose, or with the Gauss-Markov error
:func:`gnssacc.factors.gnss_position_gm_factor` on (X, G).

Nodes
-----
The smoother puts a node at every fix after the start, at most one per ``[smoother]
min_node_spacing_s`` (:func:`node_fixes`); a fix between two nodes (faster fixes) is a factor on
the earlier node through the IMU preintegrated up to the fix
(:func:`gnssacc.factors.preintegrated_position_factor`), so the number of nodes, and the time
per second of data, stay those of ``min_node_spacing_s`` whatever the fix rate.

Consistency
-----------
EKF: the position NIS (update kind ``pos``). Smoother: the whitened residuals of each estimate
to its nodes' fixes against their expectation (:func:`residual_chi2`), ``nis_pos_mean``.
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit

from ...core.rotations import skew
from ..mechanization import radii
from ..layout import GNSS_ERROR, I_ATT, I_POS, SYM_B, SYM_G, SYM_V, SYM_X, MarkovBlock
from ..small_linalg import matvec
from .base import AidSpec, EkfAid, Measurement, SmootherAid

#: Order at equal times: after the vehicle aids (their updates are in a GNSS epoch's prior).
ORDER = 2
_NO_GM = np.zeros(3)


def gnss_error_states(settings) -> tuple[MarkovBlock, ...]:
    """The Gauss-Markov fix-error states of ``settings`` (either estimator's), when modelled."""
    g = settings.gnss
    return (MarkovBlock(GNSS_ERROR, g.gm_tau, g.gm_sigma),) if g.gauss_markov else ()


@njit(cache=True)
def position_model(pos, R_nb, lever_b, lat, lon, h, gm, i_gm, n):
    """``dz`` (3,) [m, NED] and ``H`` (3, n) of :func:`position` for the state ``pos`` (lat, lon
    [rad], h [m]) and ``R_nb``, ``i_gm`` the index of the Gauss-Markov fix error's first state
    (-1: not modelled) and ``gm`` (3,) its nominal value [m, NED], ``n`` states; compiled (the
    EKF's per-fix path), with numpy's arithmetic (:mod:`gnssacc.estimators.small_linalg`). The
    radii are :func:`gnssacc.estimators.mechanization.radii`'s."""
    R_M, R_N = radii(pos[0])
    l_n = matvec(R_nb, lever_b, R_nb.strides[1] < R_nb.strides[0])
    dz = np.empty(3)
    dz[0] = (pos[0] - lat) * (R_M + pos[2]) + l_n[0]
    dz[1] = (pos[1] - lon) * (R_N + pos[2]) * math.cos(pos[0]) + l_n[1]
    dz[2] = -(pos[2] - h) + l_n[2]
    # H = [I, 0, -[l_n x], 0 ...]
    H = np.zeros((3, n))
    p, a = I_POS, I_ATT
    H[0, p] = H[1, p + 1] = H[2, p + 2] = 1.0
    H[0, a + 1], H[0, a + 2] = l_n[2], -l_n[1]
    H[1, a], H[1, a + 2] = -l_n[2], l_n[0]
    H[2, a], H[2, a + 1] = l_n[1], -l_n[0]
    if i_gm >= 0:
        for r in range(3):
            dz[r] += gm[r]
            H[r, i_gm + r] = 1.0
    return dz, H


def position(
    s,
    lat: float,
    lon: float,
    h: float,
    sigma_ned: np.ndarray,
    lever_arm_b: np.ndarray,
    gate: float = 0.0,
    cov_ned: np.ndarray | None = None,
) -> Measurement:
    """GNSS antenna position fix (lat, lon [rad], h [m]) with 1-sigma ``sigma_ned`` [m], or with
    the full NED covariance ``cov_ned`` [m^2] (correlated axes, e.g. an RTKLIB solution's) when
    given (module notes; the model is :func:`position_model`)."""
    i_gm = s.layout.offset(GNSS_ERROR)
    gm = s.gm if i_gm >= 0 else _NO_GM
    dz, H = position_model(s.pos, s.R_nb, lever_arm_b, lat, lon, h, gm, i_gm, s.P.shape[0])
    if cov_ned is None:
        R = np.zeros((3, 3))
        R[0, 0], R[1, 1], R[2, 2] = sigma_ned[0] ** 2, sigma_ned[1] ** 2, sigma_ned[2] ** 2
    else:
        R = np.asarray(cov_ned, float)
    return Measurement("pos", dz, H, R, gate)


class EkfPosition(EkfAid):
    """The position update at every fix (gated by ``[ekf] position_gate_nis``)."""

    order, epoch = ORDER, "gnss"

    def __init__(self, ctx):
        settings = ctx.settings
        self.fixes = settings.gnss.fixes(ctx.run.gnss)
        self.t = self.fixes.t
        self.lever = settings.gnss.lever_arm_b
        self.gate = settings.position_gate_nis
        self.states = gnss_error_states(settings)

    def models(self, s, j: int) -> list[Measurement]:
        g = self.fixes
        cov = None if g.corr_ned is None else g.cov_ned(j)  # correlated axes: the full covariance
        return [position(s, g.lat[j], g.lon[j], g.h[j], g.sigma_ned[j], self.lever, self.gate, cov)]

    def compiled(self) -> tuple[str, tuple]:
        """``("position", (lat, lon, h, R, lever, gate))``: the fixes [rad, rad, m], their noise
        covariances (K, 3, 3) [m^2] as :func:`position` makes them, the lever arm [m, body] and
        the gate."""
        g = self.fixes
        return "position", (
            *(np.ascontiguousarray(x, float) for x in (g.lat, g.lon, g.h)),
            fix_noise(g),
            np.ascontiguousarray(self.lever, float),
            float(self.gate),
        )


def fix_noise(fixes) -> np.ndarray:
    """Every fix's noise covariance (K, 3, 3) [m^2, NED], to the bit as :func:`position` takes it:
    ``diag(sigma^2)`` squared as a numpy scalar squares (the C library's ``pow``, which may round
    otherwise than ``sigma * sigma``), or the stated covariance with correlated axes."""
    k = len(fixes.t)
    if fixes.corr_ned is not None:
        return np.ascontiguousarray(fixes.cov_ned(np.arange(k)), float)
    R = np.zeros((k, 3, 3))
    for i in range(3):
        R[:, i, i] = [v**2 for v in np.asarray(fixes.sigma_ned[:, i], float).tolist()]
    return R


def node_fixes(fix_t: np.ndarray, min_spacing: float) -> np.ndarray:
    """Which fixes are nodes (a mask): the first, then each fix at least ``min_spacing`` [s] after
    the last one taken, less half the median fix interval (fixes at a steady rate up to
    ``1 / min_spacing`` are all taken, jitter or not; at 20 Hz every tenth for 0.5 s). The others
    are folded into the node before them; ``min_spacing <= 0``: every fix is a node."""
    keep = np.ones(len(fix_t), bool)
    if min_spacing <= 0 or len(fix_t) < 2:
        return keep
    step = min_spacing - 0.5 * float(np.median(np.diff(fix_t)))
    last = -np.inf
    for k, t in enumerate(fix_t.tolist()):
        if t - last >= step:
            last = t
        else:
            keep[k] = False
    return keep


def folded_by_node(times: np.ndarray, fix_t: np.ndarray, is_node_fix: np.ndarray) -> dict:
    """``{node i: [fix indices]}``: the fixes that are not nodes, strictly between nodes ``i - 1``
    and ``i`` (their factors go on node ``i - 1`` with node ``i``'s update)."""
    k = np.flatnonzero(~is_node_fix & (fix_t > times[0]) & (fix_t < times[-1]))
    k = k[~np.isin(fix_t[k], times)]
    out: dict = {}
    for kk, i in zip(
        k.tolist(), np.searchsorted(times, fix_t[k], side="right").tolist(), strict=True
    ):
        out.setdefault(i, []).append(kk)
    return out


def residual_chi2(
    rec, idx: np.ndarray, p_fix: np.ndarray, cov_fix: np.ndarray, lever_b: np.ndarray, gm=None
) -> tuple[np.ndarray, np.ndarray]:
    r"""Whitened squared residuals of GNSS factors at nodes ``idx`` of an estimate, and their
    expectations.

    ``r = p_fix - (t + R l + g)`` (``g`` the GNSS error, when modelled). For a consistent estimate
    that includes the fix, ``E[r^T Sigma^-1 r] = tr(Sigma^-1 C_r)`` with ``C_r = Sigma - J C J^T``
    (``C`` the joint marginal of the pose and ``g``, ``J = [-R [l x], R, I]`` on GTSAM's
    (rotation, translation) tangent and ``g``). The consistency figure is the ratio of their sums
    (:meth:`SmootherPosition.score`): 1 when consistent, and never dominated by a node whose
    ``C_r`` is close to zero (the pose and GNSS-error marginals nearly cancel there).

    Parameters
    ----------
    rec : gnssacc.estimators.smoother.NodeRecord
        The estimate (``R``, ``p_n``, ``cov_pose`` per node).
    idx : ndarray (K,) of int
        Nodes with a fix.
    p_fix : ndarray (K, 3)
        Their fixes (tangent frame) [m].
    cov_fix : ndarray (K, 3, 3)
        The fixes' white covariance [m^2] (:meth:`gnssacc.core.recording.GnssFixes.cov_ned`).
    lever_b : ndarray (3,)
    gm : tuple, optional
        ``(g, cov_g, cov_xg)`` of the nodes ``idx``: the GNSS error's estimate (K, 3), its
        covariance (K, 3, 3) and its cross-covariance with the pose tangent (K, 6, 3); zero
        without that model.

    Returns
    -------
    chi2, expected : ndarray (K,)
    """
    R = rec.R[idx]
    g, cov_g, cov_xg = gm if gm is not None else (0.0, 0.0, np.zeros((len(idx), 6, 3)))
    r = p_fix - (rec.p_n[idx] + R @ lever_b + g)
    J = np.concatenate([-R @ skew(lever_b), R], axis=2)
    cross = J @ cov_xg
    JCJ = J @ rec.cov_pose[idx] @ J.transpose(0, 2, 1) + cov_g + cross + cross.transpose(0, 2, 1)
    W = np.linalg.inv(cov_fix)
    chi2 = np.einsum("ki,kij,kj->k", r, W, r)
    expected = 3.0 - np.einsum("kij,kji->k", W, JCJ)
    return chi2, np.maximum(expected, 0.0)


class SmootherPosition(SmootherAid):
    """The fixes' factors on the smoother's nodes (module notes)."""

    order = 0

    def __init__(self, ctx):
        run, settings = ctx.run, ctx.settings
        self.stats = ctx.stats
        self.fixes = settings.gnss.fixes(run.gnss)
        self.p_fix = run.origin.to_ned(self.fixes.lat, self.fixes.lon, self.fixes.h)
        self.fix_at = {float(t): i for i, t in enumerate(self.fixes.t)}
        self.lever = settings.gnss.lever_arm_b
        self.has_lever = bool(np.any(self.lever != 0))
        self.gm_sigma, self.gm_tau = settings.gnss.gm_sigma, settings.gnss.gm_tau
        self.states = gnss_error_states(settings)
        self.gm = bool(self.states)
        self.is_node_fix = node_fixes(self.fixes.t, settings.min_node_spacing_s)
        self._noise: dict = {}

    def node_epochs(self, existing: np.ndarray) -> np.ndarray:
        return self.fixes.t[self.is_node_fix]

    def attach(self, ctx) -> None:
        self.folded = folded_by_node(ctx.times, self.fixes.t, self.is_node_fix)
        self.fix_of = np.full(len(ctx.times), -1)

    def interval(self, graph, ctx, i: int) -> None:
        """The fixes between node ``i - 1`` and node ``i`` on node ``i - 1``'s variables, through
        the IMU preintegrated from node ``i - 1`` to each (and with the GNSS error of both nodes
        when modelled: then the fixes of the interval are one factor, their deviations from the
        bridge between the nodes being one path of the wander)."""
        folded = self.folded.get(i, ())
        if len(folded) == 0:
            return
        import gtsam

        from ...factors import preintegrated_position_factor, preintegrated_positions_factor

        keys, gm = tuple(gtsam.symbol(c, i - 1) for c in (SYM_X, SYM_V, SYM_B)), None
        if self.gm:
            keys += (gtsam.symbol(SYM_G, i - 1), gtsam.symbol(SYM_G, i))
            gm = (self.gm_tau, self.gm_sigma, ctx.times[i] - ctx.times[i - 1])
        pims, R_fs = zip(*(self._carried(ctx, i, k) for k in folded))
        covs = [self.fixes.cov_ned(k) for k in folded]
        if gm is not None and len(folded) > 1:
            graph.add(
                preintegrated_positions_factor(
                    keys, list(pims), self.p_fix[list(folded)], self.lever, covs, list(R_fs), gm
                )
            )
        else:
            for k, pim, R_f, cov in zip(folded, pims, R_fs, covs, strict=True):
                graph.add(
                    preintegrated_position_factor(
                        keys, pim, self.p_fix[k], self.lever, cov, R_f, gm
                    )
                )
        self.stats["n_gps_folded"] += len(folded)

    def _carried(self, ctx, i: int, k: int) -> tuple:
        """The IMU preintegrated from node ``i - 1`` to fix ``k`` and the attitude it predicts
        there from the node's estimate (for the factor's noise)."""
        import gtsam

        pim = ctx.preintegrate_to(i, float(self.fixes.t[k]))
        prev = ctx.prev
        nav = pim.predict(gtsam.NavState(prev.pose, prev.v_n), prev.bias)
        return pim, nav.attitude().matrix()

    def node(self, graph, ctx, i: int, t: float, pred) -> None:
        """The GPS factor on node ``i`` when a fix is at its time ``t``."""
        k = self.fix_at.get(float(t))
        if k is None:
            return
        import gtsam

        from ...factors import gnss_position_gm_factor

        g = self.fixes
        sig = g.sigma_ned[k]
        cov = None if g.corr_ned is None else g.cov_ned(k)  # correlated axes: the full covariance
        self.stats["n_gps_factors"] += 1
        self.fix_of[i] = k
        x = gtsam.symbol(SYM_X, i)
        if self.gm:
            graph.add(
                gnss_position_gm_factor(
                    x, gtsam.symbol(SYM_G, i), self.p_fix[k], self.lever, sig, cov
                )
            )
            return
        key = tuple(sig) if cov is None else tuple(cov.ravel())
        noise = self._noise.get(key)
        if noise is None:  # most runs have a handful of distinct fix sigmas
            noise = self._noise[key] = (
                gtsam.noiseModel.Diagonal.Sigmas(sig)
                if cov is None
                else gtsam.noiseModel.Gaussian.Covariance(cov)
            )
        if self.has_lever:
            graph.add(gtsam.GPSFactorArm(x, self.p_fix[k], self.lever, noise))
        else:
            graph.add(gtsam.GPSFactor(x, self.p_fix[k], noise))

    def score(self, ctx, rec) -> dict:
        """``nis_pos_mean``: the estimate's whitened residuals to its nodes' fixes over their
        expectation (:func:`residual_chi2`; 1 when consistent), and ``n_pos_updates``."""
        idx = np.flatnonzero((self.fix_of >= 0) & rec.done)
        k = self.fix_of[idx]
        gm = None
        if self.gm:
            g, cov_g, cov_xg = rec.markov_of(GNSS_ERROR)
            gm = (g[idx], cov_g[idx], cov_xg[idx])
        c = np.column_stack(
            residual_chi2(rec, idx, self.p_fix[k], self.fixes.cov_ned(k), self.lever, gm)
        ).reshape(-1, 2)
        c = c[np.isfinite(c[:, 0])]
        ratio = float(c[:, 0].sum() / c[:, 1].sum()) if len(c) and c[:, 1].sum() > 0 else None
        return {"n_pos_updates": len(c), "nis_pos_mean": ratio}


AID = AidSpec(
    name="gnss_position",
    kinds=("pos",),
    ekf=EkfPosition,
    smoother=SmootherPosition,
    smoother_counts={"n_gps_factors": 0, "n_gps_folded": 0},
    noise_keys=(("gnss", "sigma_scale"),),
    stage="imu",
)
