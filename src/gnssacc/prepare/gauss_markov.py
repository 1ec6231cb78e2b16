"""The ``-gm`` methods' own setup: the Gauss-Markov GNSS error model for one prepared recording.

``ekf-gm`` and ``smoother-gm`` are ``ekf`` and ``smoother`` with three more states for the
time-correlated part of the fix errors (first-order Gauss-Markov per N/E/D axis, ``[gnss]
gm_sigma_m`` and ``gm_tau_s``), whatever the noise identification decided for the baselines.
Their parameters, first found wins (:func:`gm_setup`):

1. the run's configuration already has ``gm_sigma_m > 0`` (set by the user, or kept by the
   tuner's Gauss-Markov stage): then the ``-gm`` method is its baseline, run under its own id;
2. the tuner ran (``--tune auto``) but kept white fixes: a Gauss-Markov search for this run
   alone, the tuned IMU noise held (:func:`gnssacc.prepare.tuning.tune_gauss_markov`);
3. ``--tune none`` on fixes made from the truth with a Gauss-Markov noise profile (``--noise gm``
   on a simulated run, KITTI or a CSV run with truth): the profile's own parameters, the known
   noise, as the IMU noise of a ``sim:`` source is the simulator's;
4. otherwise :class:`gnssacc.core.errors.InputError`: ``gm_sigma_m`` must be set.

The white part of a fix's sigma is then ``gnss.sigma_scale`` times its stated sigma (in case 3,
the profile's white sigma over its total).
"""

from __future__ import annotations

from dataclasses import replace

import numpy as np

from ..core.errors import InputError
from ..sources.gnss_noise import PROFILES
from .filter_pass import FilterPass
from .tuning import tune_gauss_markov


def gm_setup(prep, *, filter_pass: FilterPass) -> tuple:
    """The prepared recording the ``-gm`` methods run with, and how it was found.

    Parameters
    ----------
    prep : gnssacc.prepare.prepared.Prepared
    filter_pass : FilterPass
        For the Gauss-Markov search (case 2 of the module notes).

    Returns
    -------
    prep : Prepared
        A copy with ``cfg`` holding ``gm_sigma_m > 0`` and a ``gnss.sigma_scale`` that makes the
        fixes' stated sigmas the white part.
    how : dict
        ``source`` (``config``, ``tuner (its Gauss-Markov stage)``, ``tuner``, ``noise profile``),
        ``gm_sigma_m`` [m], ``gm_tau_s`` [s], ``sigma_scale`` and, for the tuner, ``loglik_gain``.
    """
    cfg, how = prep.cfg, {}
    if np.any(cfg.gnss_gm_sigma > 0):
        out = prep
        how["source"] = (
            "config" if ("gnss", "gm_sigma_m") in cfg.explicit else "tuner (its Gauss-Markov stage)"
        )
    elif prep.tuning is not None:
        cfg, info = tune_gauss_markov(
            prep.run, cfg, prep.stationary, prep.quality, prep.init, filter_pass=filter_pass
        )
        out = replace(prep, cfg=cfg)
        how.update(source="tuner", loglik_gain=info["loglik_gain"], seconds=info["seconds"])
    else:
        out = _from_profile(prep)
        how["source"] = "noise profile"
    how.update(
        gm_sigma_m=out.cfg.gnss_gm_sigma.tolist(),
        gm_tau_s=out.cfg.gnss_gm_tau.tolist(),
        sigma_scale=float(out.cfg["gnss"]["sigma_scale"]),
    )
    return out, how


def _from_profile(prep):
    """Case 3 of the module notes (the known noise profile), else the InputError of case 4."""
    profile = PROFILES.get(prep.run.meta.get("noise"))
    if (
        profile is None
        or not np.any(profile["gm_sigma"] > 0)
        or ("gnss", "gm_sigma_m") in prep.cfg.explicit
    ):
        raise InputError(
            "gnss.gm_sigma_m",
            "the -gm methods need the Gauss-Markov fix-error model: set [gnss] "
            "gm_sigma_m (> 0) and gm_tau_s in the configuration, or use --tune auto",
        )
    total = np.sqrt(profile["gm_sigma"] ** 2 + profile["white_sigma"] ** 2)
    white_ratio = float(np.mean(profile["white_sigma"] / total))  # the fixes state the total sigma
    scale = white_ratio * float(prep.cfg["gnss"]["sigma_scale"])
    cfg = prep.cfg.with_values(
        {
            "gnss": {
                "gm_sigma_m": profile["gm_sigma"].tolist(),
                "gm_tau_s": profile["tau_s"],
                "sigma_scale": scale,
            }
        },
        f"noise profile {prep.run.meta['noise']}",
    )
    return replace(prep, cfg=cfg)
