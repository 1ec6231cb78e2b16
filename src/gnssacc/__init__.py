"""gnssacc: INS/GNSS state estimation with GNSS-derived acceleration aiding.

Implements the error-state EKF of Versano & Klein, "Enhanced INS/GNSS State Estimation using
GNSS-Based Acceleration Measurements", and its GTSAM iSAM2 fixed-lag smoother twin, with
recorded-run ingestion (ROS 1 / ROS 2 / MCAP bags, CSV run directories, the KITTI sequence in the
gtsam wheel), input checks, self-tuning, metrics and reports.

Python API (the command line's twin, :mod:`gnssacc.api`)::

    import gnssacc
    res = gnssacc.process("kitti", methods=["ekf", "ekf-acc"])   # gnssacc.run(...) is the same
    print(res.table())
    run = gnssacc.load("run.bag")            # a RecordedRun
    sim = gnssacc.simulate("car", 300.0)     # a RecordedRun with truth

Conventions (every module follows them; they are stated here once):

* **Frames.** Navigation frame ``n``: local North-East-Down (a tangent plane at a stated origin
  for metric work: smoother nodes, the least-squares GNSS acceleration). Body frame ``b``:
  Front-Right-Down, the IMU axes after the configured mounting rotation (ROS FLU/ENU data are
  converted at the source). Names carry frames: ``v_n``, ``f_b``, ``omega_ib_b``; rotations are
  named by their frames, ``R_nb`` maps b to n.
* **Error state** (EKF): ``dx = [dp_n (N, E, D) [m], dv_n [m/s], phi [rad], b_a [m/s^2],
  b_g [rad/s]]``, estimate minus truth, with the attitude error ``phi`` resolved in n and
  ``R_nb_est = (I + [phi x]) R_nb_true``; innovations are predicted minus measured.
* **Units.** SI and radians inside; degrees (and deg/h, mg) only at the edges: configuration
  files, CSV outputs, printed tables. Time in seconds on one clock (the GNSS clock after any
  configured or measured IMU clock offset).
* **Positions.** Geodetic latitude and longitude [rad] and ellipsoidal height [m], of the IMU
  (body origin); the GNSS antenna sits at the configured lever arm in b.
"""

from .core.jit import configure_cache as _configure_cache
from .core.version import __version__  # noqa: F401 (the package attribute)

_configure_cache()  # before anything imports numba: a read-only install caches in the user's folder

#: The API, imported when first used (so ``gnssacc --help`` stays instant).
_API = ("process", "run", "load", "simulate", "configure", "evaluate", "Result")


def __getattr__(name):
    if name in _API:
        from . import api

        return getattr(api, name)
    raise AttributeError(f"module 'gnssacc' has no attribute {name!r}")


def __dir__():
    return sorted(list(globals()) + list(_API))
