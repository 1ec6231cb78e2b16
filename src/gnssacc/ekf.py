"""The paper's 15-state error-state EKF with GNSS position and GNSS-derived acceleration updates.

Prediction runs through the numba kernel in :mod:`gnssacc.mechanization` at every IMU sample;
updates happen at GNSS epochs: the position update with ``H_p = [I, 0, -[(R l_b) x], 0, 0]``
(``l_b`` the antenna lever arm; ``H_p = [I 0 0 0 0]`` without one, as in the paper) and, for
``ekf-acc``, the acceleration update with ``H_a`` from :mod:`gnssacc.gnss_accel`. Innovations
are predicted minus measured and the error state is estimate minus truth, so the closed-loop
feedback subtracts the estimated errors (paper: ``dx+ = K dz``, closed loop).

The covariance update uses the Joseph form, algebraically equal to the paper's ``(I - K H) P``
for the optimal gain and numerically safer.
"""
from __future__ import annotations

import time
from dataclasses import dataclass

import numpy as np

from . import mechanization as mech
from .config import RunConfig
from .earth import gravity_n, radii
from .gnss_accel import AccelWindow, H_a_blocks, measured_specific_force, predicted_acceleration
from .initialise import initial_sigmas, initialise
from .progress import progress
from .quality import QualityReport, check_imu, inflation_segments
from .rotations import dcm_to_euler, euler_error_jacobian, rotvec_to_dcm, skew
from .run import InitialState, RecordedRun
from .solution import NavSolution

METHODS = {"ekf": False, "ekf-acc": True}


@dataclass
class _State:
    pos: np.ndarray   # lat, lon [rad], h [m]
    v_n: np.ndarray   # [m/s]
    R_nb: np.ndarray
    b_a: np.ndarray   # accumulated accelerometer bias estimate [m/s^2]
    b_g: np.ndarray   # accumulated gyro bias estimate [rad/s]
    P: np.ndarray     # 15 x 15


def _initial_state(init: InitialState, cfg: RunConfig) -> _State:
    sig_p, sig_v, sig_att = initial_sigmas(init, cfg)
    P = np.zeros((15, 15))
    sig = np.concatenate([sig_p, sig_v, sig_att, cfg.accel_bias_sigma0, cfg.gyro_bias_sigma0])
    P[np.diag_indices(15)] = sig**2
    return _State(np.array([init.lat, init.lon, init.h]), np.array(init.v_n, float).copy(), init.R_nb.copy(),
                  np.zeros(3), np.zeros(3), P)


def _correct(s: _State, dx: np.ndarray) -> None:
    """Closed-loop feedback of an estimated error (estimate minus truth) into the nominal state."""
    R_M, R_N = radii(s.pos[0])
    s.pos[0] -= dx[0] / (R_M + s.pos[2])
    s.pos[1] -= dx[1] / ((R_N + s.pos[2]) * np.cos(s.pos[0]))
    s.pos[2] += dx[2]
    s.v_n -= dx[3:6]
    s.R_nb = rotvec_to_dcm(-dx[6:9]) @ s.R_nb
    # f_est = f_raw - b_a_hat carries the residual b_a; removing it means adding it to b_a_hat.
    s.b_a += dx[9:12]
    s.b_g += dx[12:15]


def _update(s: _State, dz: np.ndarray, H: np.ndarray, R: np.ndarray, gate: float = 0.0) -> float:
    """Kalman update with innovation ``dz`` (predicted minus measured); returns the NIS.

    A positive ``gate`` rejects the update (returning ``-NIS``) when NIS exceeds it.
    """
    PHt = s.P @ H.T
    S = H @ PHt + R
    S_inv = np.linalg.inv(S)
    nis = float(dz @ S_inv @ dz)
    if gate > 0.0 and nis > gate:
        return -nis
    K = PHt @ S_inv
    _correct(s, K @ dz)
    IKH = np.eye(15) - K @ H
    s.P = IKH @ s.P @ IKH.T + K @ R @ K.T
    return nis


def _position_innovation(s: _State, lat, lon, h, lever_arm_b):
    """Antenna position predicted minus measured, in NED metres, and H_p."""
    R_M, R_N = radii(s.pos[0])
    l_n = s.R_nb @ lever_arm_b
    dz = np.array([(s.pos[0] - lat) * (R_M + s.pos[2]), (s.pos[1] - lon) * (R_N + s.pos[2]) * np.cos(s.pos[0]),
                   -(s.pos[2] - h)]) + l_n
    H = np.zeros((3, 15))
    H[:, 0:3] = np.eye(3)
    H[:, 6:9] = -skew(l_n)
    return dz, H


class _Recorder:
    """Collects the output rows; memory grows with the outputs only."""

    def __init__(self, n: int, store_P: bool):
        self.t = np.empty(n)
        self.pos = np.empty((n, 3))
        self.v_n = np.empty((n, 3))
        self.rpy = np.empty((n, 3))
        self.b_a = np.empty((n, 3))
        self.b_g = np.empty((n, 3))
        self.sigma = np.empty((n, 15))
        self.P = np.empty((n, 15, 15)) if store_P else None
        self.n = 0

    def add(self, t: float, s: _State) -> None:
        i = self.n
        self.t[i] = t
        self.pos[i] = s.pos
        self.v_n[i] = s.v_n
        rpy = np.array(dcm_to_euler(s.R_nb))
        self.rpy[i] = rpy
        self.b_a[i] = s.b_a
        self.b_g[i] = s.b_g
        d = np.sqrt(np.maximum(np.diag(s.P), 0.0))
        J = euler_error_jacobian(*rpy)
        d[6:9] = np.sqrt(np.maximum(np.diag(J @ s.P[6:9, 6:9] @ J.T), 0.0))
        self.sigma[i] = d
        if self.P is not None:
            self.P[i] = s.P
        self.n += 1

    def solution(self, method: str, runtime_s: float, stats: dict) -> NavSolution:
        n = self.n
        return NavSolution(method, self.t[:n], self.pos[:n, 0], self.pos[:n, 1], self.pos[:n, 2], self.v_n[:n],
                           self.rpy[:n], self.b_a[:n], self.b_g[:n], self.sigma[:n], runtime_s, stats,
                           None if self.P is None else self.P[:n])


@dataclass
class EkfSetup:
    """Everything the EKF's event loop needs, prepared once (shared with analysis replays)."""

    init: InitialState
    state: _State
    imu_t: np.ndarray
    f_imu: np.ndarray
    w_imu: np.ndarray
    kernel_args: tuple      # noise PSDs, inflation segments, phi order, with_cov for mech.propagate
    seg_i0: np.ndarray
    seg_i1: np.ndarray
    gate: float
    lever_b: np.ndarray
    f_avg_s: float
    p_fix_n: np.ndarray     # fixes in the run's tangent frame [m]
    window: AccelWindow
    k: int                  # IMU index of the sample holding at init.t

    @property
    def t0(self) -> float:
        return float(self.init.t)


def prepare(run: RecordedRun, cfg: RunConfig, init: InitialState | None = None,
            quality: QualityReport | None = None) -> EkfSetup:
    """Initial state and covariance, IMU arrays, noise and inflation, acceleration window."""
    init = init or run.init or initialise(run, cfg)
    if quality is None:
        quality = check_imu(run.imu, cfg)
    seg_i0, seg_i1, seg_qg, seg_qa = inflation_segments(run.imu, quality, cfg)
    imu_t = np.ascontiguousarray(run.imu.t, float)
    kernel_args = (cfg.accel_psd, cfg.gyro_psd, cfg.accel_bias_rw_psd, cfg.gyro_bias_rw_psd, seg_i0, seg_i1, seg_qa,
                   seg_qg, int(cfg["ekf"]["phi_order"]), True)
    gnss = run.gnss
    return EkfSetup(init, _initial_state(init, cfg), imu_t, np.ascontiguousarray(run.imu.f_b, float),
                    np.ascontiguousarray(run.imu.omega_ib_b, float), kernel_args, seg_i0, seg_i1,
                    float(cfg["ekf"]["position_gate_nis"]), cfg.lever_arm_b, float(cfg["accel"]["specific_force_avg_s"]),
                    run.origin.to_ned(gnss.lat, gnss.lon, gnss.h),
                    AccelWindow(int(cfg["accel"]["window"]), float(cfg["accel"]["max_gap_s"]), cfg.accel_sigma_override),
                    int(np.searchsorted(imu_t, float(init.t), side="right")))


def acceleration_model(run: RecordedRun, setup: EkfSetup, s: _State, t: float, meas):
    """Innovation (predicted minus measured), H_a and R of the acceleration update at ``t``.

    Returns ``None`` when the specific force it needs comes from a suspect IMU span
    (fabricated or damaged data): the update is then skipped.
    """
    f_meas = measured_specific_force(run.imu, t, setup.f_avg_s, setup.seg_i0, setup.seg_i1)
    if f_meas is None:
        return None
    f_b = f_meas - s.b_a
    a_pred = predicted_acceleration(s.R_nb, f_b, gravity_n(s.pos[0], s.pos[2]))
    d_phi, d_ba = H_a_blocks(s.R_nb, f_b)
    H = np.zeros((3, 15))
    H[:, 6:9] = d_phi
    H[:, 9:12] = d_ba
    return a_pred - meas.a_n, H, meas.cov


def default_output_times(run: RecordedRun) -> np.ndarray:
    """Truth epochs when there is truth, else GNSS epochs (before outages were applied)."""
    if run.truth is not None:
        return run.truth.t
    return run.gnss.t


def run_ekf(run: RecordedRun, cfg: RunConfig, method: str = "ekf", *, output_times: np.ndarray | None = None,
            quality: QualityReport | None = None, init: InitialState | None = None,
            store_P: bool = False, record_innovations: bool = False, show_progress: bool = False) -> NavSolution:
    """Run the EKF over a recorded run.

    Parameters
    ----------
    run : RecordedRun
    cfg : RunConfig
    method : {"ekf", "ekf-acc"}
        ``ekf``: position updates only (the paper's baseline); ``ekf-acc``: position and
        GNSS-derived acceleration updates (the paper's method).
    output_times : ndarray, optional
        Epochs [s] at which to report the state (after any update at the same time). Default:
        :func:`default_output_times`. Epochs before the filter starts are skipped.
    quality : QualityReport, optional
        Data-quality findings; computed with :func:`gnssacc.quality.check_imu` when omitted.
        Suspect IMU spans get inflated process noise.
    init : InitialState, optional
        Overrides ``run.init`` and self-initialisation.
    store_P : bool
        Keep the full covariance at every output epoch.
    record_innovations : bool
        Keep every update's time and normalised innovation squared in ``stats`` (``nis_pos_t``,
        ``nis_pos``, ``nis_acc_t``, ``nis_acc``), e.g. for tuning.
    show_progress : bool
        Show a progress bar (only on a terminal).

    Returns
    -------
    NavSolution
    """
    if method not in METHODS:
        raise ValueError(f"unknown EKF method {method!r}; known: {', '.join(METHODS)}")
    use_acc = METHODS[method]
    wall0 = time.perf_counter()
    setup = prepare(run, cfg, init, quality)
    s, imu_t, kargs, t0, k = setup.state, setup.imu_t, setup.kernel_args, setup.t0, setup.k
    t_cur = t0
    out_t = default_output_times(run) if output_times is None else np.asarray(output_times, float)
    out_t = out_t[(out_t >= t0) & (out_t <= imu_t[-1])]
    gnss, p_fix_n, window = run.gnss, setup.p_fix_n, setup.window

    # Events in time order; at equal times the GNSS update comes before the output.
    ev_t = np.concatenate([gnss.t, out_t])
    ev_kind = np.concatenate([np.zeros(len(gnss), int), np.ones(len(out_t), int)])
    ev_idx = np.concatenate([np.arange(len(gnss)), np.arange(len(out_t))])
    order = np.lexsort((ev_kind, ev_t))
    rec = _Recorder(len(out_t), store_P)
    stats = {"n_pos_updates": 0, "n_acc_updates": 0, "n_pos_rejected": 0, "n_acc_skipped_suspect_imu": 0,
             "init": setup.init.how, "t_init": t0}
    nis = {"pos": [], "pos_t": [], "acc": [], "acc_t": []}

    for e in progress(order, desc=method, enable=show_progress):
        t_e, kind, i = ev_t[e], ev_kind[e], ev_idx[e]
        if t_e > imu_t[-1]:
            break
        if kind == 0:
            meas = window.push(t_e, p_fix_n[i], gnss.sigma_ned[i])
            if t_e < t0:
                continue
        if t_e > t_cur:
            k, t_cur = mech.propagate(imu_t, setup.f_imu, setup.w_imu, k, t_cur, t_e, s.pos, s.v_n, s.R_nb, s.b_a,
                                      s.b_g, s.P, *kargs)
        if kind == 1:
            rec.add(t_e, s)
            continue
        dz, H = _position_innovation(s, gnss.lat[i], gnss.lon[i], gnss.h[i], setup.lever_b)
        nis_p = _update(s, dz, H, np.diag(gnss.sigma_ned[i] ** 2), setup.gate)
        if nis_p < 0:
            stats["n_pos_rejected"] += 1
        else:
            stats["n_pos_updates"] += 1
            nis["pos"].append(nis_p)
            nis["pos_t"].append(t_e)
        if use_acc and meas is not None:
            model = acceleration_model(run, setup, s, t_e, meas)
            if model is None:
                stats["n_acc_skipped_suspect_imu"] += 1
                continue
            nis["acc"].append(_update(s, *model))
            nis["acc_t"].append(t_e)
            stats["n_acc_updates"] += 1

    runtime = time.perf_counter() - wall0
    for key in ("pos", "acc"):
        vals = np.asarray(nis[key])
        # Normalised innovation squared per degree of freedom: ~1 for a consistent filter.
        stats[f"nis_{key}_mean"] = float(vals.mean() / 3.0) if vals.size else None
        if record_innovations:
            stats[f"nis_{key}"] = vals / 3.0
            stats[f"nis_{key}_t"] = np.asarray(nis[key + "_t"])
    stats["accel_window_resets"] = window.resets
    return rec.solution(method, runtime, stats)
