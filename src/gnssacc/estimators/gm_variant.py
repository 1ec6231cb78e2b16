"""The ``-gm`` methods: position-only estimators with the Gauss-Markov GNSS error states on.

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

from ..analysis.consistency import ModelCheck
from ..core.errors import InputError
from ..prepare.identify import Identified
from ..prepare.tuning import scaled_gnss, tune_gauss_markov
from ..sources.gnss_noise import PROFILES
from .ekf import run_ekf

#: The ``-gm`` methods and the baseline each one runs as.
BASE_OF = {"ekf-gm": "ekf", "smoother-gm": "smoother"}


def gm_setup(ident: Identified) -> tuple[Identified, dict]:
    """The identified run and configuration the ``-gm`` methods run with, and how they were found.

    Returns
    -------
    ident : Identified
        A copy with ``cfg`` holding ``gm_sigma_m > 0`` and ``run``'s fix sigmas the white part.
    how : dict
        ``source`` (``config``, ``tuner (its Gauss-Markov stage)``, ``tuner``, ``noise profile``),
        ``gm_sigma_m`` [m], ``gm_tau_s`` [s],
        ``sigma_scale`` and, for the tuner, ``loglik_gain``.
    Made once per identification (kept in ``ident.derived``): ``ekf-gm`` and ``smoother-gm``
    share one search.
    """
    if "gm" in ident.derived:
        return ident.derived["gm"]
    cfg, how = ident.cfg, {}
    if np.any(cfg.gnss_gm_sigma > 0):
        out = ident
        how["source"] = "config" if ("gnss", "gm_sigma_m") in cfg.explicit else "tuner (its Gauss-Markov stage)"
    elif ident.tuning is not None:
        cfg, info = tune_gauss_markov(ident.run, cfg, ident.stationary, ident.quality, ident.init)
        out = replace(ident, cfg=cfg, run=scaled_gnss(ident.run, info["run_scale"]))
        how.update(source="tuner", loglik_gain=info["loglik_gain"], seconds=info["seconds"])
    else:
        out = _from_profile(ident)
        how["source"] = "noise profile"
    how.update(gm_sigma_m=out.cfg.gnss_gm_sigma.tolist(), gm_tau_s=out.cfg.gnss_gm_tau.tolist(),
               sigma_scale=float(out.cfg["gnss"]["sigma_scale"]))
    ident.derived["gm"] = (out, how)
    return ident.derived["gm"]


def _from_profile(ident: Identified) -> Identified:
    """Case 3 of the module docstring (the known noise profile), else the InputError of case 4."""
    profile = PROFILES.get(ident.run.meta.get("noise"))
    if profile is None or not np.any(profile["gm_sigma"] > 0) or ("gnss", "gm_sigma_m") in ident.cfg.explicit:
        raise InputError("gnss.gm_sigma_m", "the -gm methods need the Gauss-Markov fix-error model: set [gnss] "
                                            "gm_sigma_m (> 0) and gm_tau_s in the configuration, or use --tune auto")
    total = np.sqrt(profile["gm_sigma"] ** 2 + profile["white_sigma"] ** 2)
    white_ratio = float(np.mean(profile["white_sigma"] / total))   # the fixes state the total sigma
    scale = white_ratio * float(ident.cfg["gnss"]["sigma_scale"])
    cfg = ident.cfg.with_values({"gnss": {"gm_sigma_m": profile["gm_sigma"].tolist(), "gm_tau_s": profile["tau_s"],
                                          "sigma_scale": scale}}, f"noise profile {ident.run.meta['noise']}")
    return replace(ident, cfg=cfg, run=scaled_gnss(ident.run, white_ratio))


def gm_model(ident: Identified, ekf_gm=None) -> tuple[Identified, ModelCheck]:
    """The ``-gm`` setup and its noise-model check (one EKF pass with the Gauss-Markov states, as
    :func:`gnssacc.prepare.identify.identify` checks the baselines' model), made once per identification:
    what the ``-gm`` methods' consistency is judged with (a smoother's own figures cannot show
    the model; the baselines' check is of the white model). ``ekf_gm``: the ``ekf-gm`` solution
    when the run has one, which is that pass (its outputs change nothing in the filter)."""
    if "gm_model" not in ident.derived:
        gm_ident, _ = gm_setup(ident)
        check = ekf_gm or run_ekf(gm_ident.run, gm_ident.cfg, "ekf", init=gm_ident.init,
                                  stationary=gm_ident.stationary, quality=gm_ident.quality,
                                  output_times=np.zeros(0))
        rest = ident.model.rest if ident.model is not None else []
        ident.derived["gm_model"] = (gm_ident, ModelCheck.from_stats(check.stats, rest))
    return ident.derived["gm_model"]


def run_gm(ident: Identified, method: str, show_progress: bool, runner) -> dict:
    """Run ``method`` (a key of :data:`BASE_OF`) through ``runner`` (the baseline's entry of
    :data:`gnssacc.pipeline.METHODS`) with the Gauss-Markov setup; solutions renamed to ``method``."""
    base = BASE_OF[method]
    gm_ident, how = gm_setup(ident)
    sols = runner(gm_ident, base, show_progress)
    out = {}
    for sid, sol in sols.items():
        new = method + sid[len(base):]
        out[new] = replace(sol, method=new, stats={**sol.stats, "gauss_markov": how})
    return out
