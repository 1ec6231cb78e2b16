"""The plain GTSAM script: what a user writes with gtsam alone for the job ``gnssacc run`` does on
KITTI (the reference of ``bench/bench_whole_run.py``; it imports nothing of gnssacc).

Reads the KITTI sequence inside the gtsam wheel (``KittiEquivBiasedImu.txt``, 100 Hz IMU in a
forward-left-up body frame; ``KittiGps_converted.txt``, 1 Hz positions in local east-north-up
metres), makes fixes from the positions with white noise (3, 3, 5 m, gnssacc's ``white``
profile), and runs GTSAM's ``IncrementalFixedLagSmoother`` (20 s lag, gnssacc's default) with a
``CombinedImuFactor`` between 1 Hz nodes and a ``GPSFactor`` per fix, with the IMU noise of
gnssacc's ``kitti`` preset (the gyro's raised: see the code). ``--sigmas`` also queries each
node's pose and velocity marginal covariances before it leaves the window (gnssacc reports them
per node). Prints the online position RMSE against the positions and the node count.

Usage::

    python bench/plain_gtsam_kitti.py [--sigmas]
"""

from __future__ import annotations

import argparse
from pathlib import Path

import gtsam
import numpy as np
from gtsam.symbol_shorthand import B, V, X

LAG_S = 20.0  # [s], gnssacc's [smoother] lag_s default


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument(
        "--sigmas", action="store_true", help="query each node's pose and velocity covariance"
    )
    args = ap.parse_args()
    data = Path(gtsam.__file__).parent / "Data"
    imu = np.loadtxt(data / "KittiEquivBiasedImu.txt", skiprows=1)
    gps = np.loadtxt(data / "KittiGps_converted.txt", skiprows=1, delimiter=",")
    t_imu, f_b, w_b = imu[:, 0], imu[:, 2:5], imu[:, 5:8]
    t_fix, p_true = gps[:, 0], gps[:, 1:4]
    sigma = np.array([3.0, 3.0, 5.0])
    p_fix = p_true + np.random.default_rng(0).normal(size=p_true.shape) * sigma

    p = gtsam.PreintegrationCombinedParams.MakeSharedU(9.81)  # ENU: gravity along -z
    # The kitti preset's noise (0.1 m/s/sqrt(h); 2 mg and 30 deg/h over 300 s), but 10 deg/sqrt(h)
    # of gyro noise: without gnssacc's inflation over the file's interpolated stretches a filter
    # needs it (the preset's notes), and 1 deg/sqrt(h) drifts 10 m RMSE off.
    p.setAccelerometerCovariance(np.eye(3) * (0.1 / 60) ** 2)
    p.setGyroscopeCovariance(np.eye(3) * np.radians(10.0 / 60) ** 2)
    p.setBiasAccCovariance(np.eye(3) * (2e-3 * 9.81) ** 2 / 300)
    p.setBiasOmegaCovariance(np.eye(3) * np.radians(30.0 / 3600) ** 2 / 300)
    p.setIntegrationCovariance(np.eye(3) * 1e-8)
    params = gtsam.ISAM2Params()
    params.setFactorization("QR")
    sm = gtsam.IncrementalFixedLagSmoother(LAG_S, params)
    gps_noise = gtsam.noiseModel.Diagonal.Sigmas(sigma)

    # The start: the first fix, the heading and speed over the first 50 m of fixes.
    k = int(np.argmax(np.linalg.norm(p_fix - p_fix[0], axis=1) > 50.0))
    d = p_fix[k] - p_fix[0]
    pose = gtsam.Pose3(gtsam.Rot3.Yaw(np.arctan2(d[1], d[0])), p_fix[0])
    vel, bias = d / (t_fix[k] - t_fix[0]), gtsam.imuBias.ConstantBias()
    graph, values, stamps = (
        gtsam.NonlinearFactorGraph(),
        gtsam.Values(),
        gtsam.FixedLagSmootherKeyTimestampMap(),
    )
    graph.add(
        gtsam.PriorFactorPose3(
            X(0), pose, gtsam.noiseModel.Diagonal.Sigmas(np.array([0.05, 0.05, 0.5, 5.0, 5.0, 5.0]))
        )
    )
    graph.add(gtsam.PriorFactorVector(V(0), vel, gtsam.noiseModel.Isotropic.Sigma(3, 2.0)))
    graph.add(
        gtsam.PriorFactorConstantBias(
            B(0),
            bias,
            gtsam.noiseModel.Diagonal.Sigmas(np.array([0.1, 0.1, 0.1, 0.01, 0.01, 0.01])),
        )
    )
    for key, value in ((X(0), pose), (V(0), vel), (B(0), bias)):
        values.insert(key, value)
        stamps.insert((key, t_fix[0]))
    sm.update(graph, values, stamps)

    est = np.full((len(t_fix), 3), np.nan)
    est[0] = pose.translation()
    j = int(np.searchsorted(t_imu, t_fix[0], side="right"))
    for n in range(1, len(t_fix)):
        pim = gtsam.PreintegratedCombinedMeasurements(p, bias)
        while j < len(t_imu) and t_imu[j] <= t_fix[n]:
            pim.integrateMeasurement(f_b[j], w_b[j], t_imu[j] - t_imu[j - 1])
            j += 1
        nav = pim.predict(gtsam.NavState(pose, vel), bias)
        graph, values, stamps = (
            gtsam.NonlinearFactorGraph(),
            gtsam.Values(),
            gtsam.FixedLagSmootherKeyTimestampMap(),
        )
        graph.add(gtsam.CombinedImuFactor(X(n - 1), V(n - 1), X(n), V(n), B(n - 1), B(n), pim))
        graph.add(gtsam.GPSFactor(X(n), p_fix[n], gps_noise))
        for key, value in ((X(n), nav.pose()), (V(n), nav.velocity()), (B(n), bias)):
            values.insert(key, value)
            stamps.insert((key, t_fix[n]))
        sm.update(graph, values, stamps)
        pose, vel = sm.calculateEstimatePose3(X(n)), sm.calculateEstimateVector(V(n))
        bias = sm.calculateEstimateConstantBias(B(n))
        est[n] = pose.translation()
        if args.sigmas:  # a node about to leave the window (1 Hz nodes)
            old = n - int(LAG_S) + 2
            if old >= 0:
                isam = sm.getISAM2()
                isam.marginalCovariance(X(old))
                isam.marginalCovariance(V(old))
    err = np.linalg.norm(est - p_true, axis=1)
    print(
        f"KITTI {t_fix[-1] - t_fix[0]:.0f} s, {len(t_fix)} nodes: position RMSE {np.sqrt(np.mean(err**2)):.2f} m "
        f"(fixes {np.sqrt(np.mean(np.sum((p_fix - p_true) ** 2, axis=1))):.2f} m)"
    )


if __name__ == "__main__":
    main()
