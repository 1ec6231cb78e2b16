"""The aids: one module per measurement, each both estimators' side of it (:mod:`.base` says what
an aid is).

=================  ===========================================================================
module             measurement
=================  ===========================================================================
``gnss_position``  the GNSS fix of the antenna (with the Gauss-Markov fix error when modelled)
``gnss_accel``     the GNSS-derived acceleration, the paper's and the window-consistent form, and
                   the paper's form fitted to the Doppler velocities
``gnss_velocity``  the receiver's Doppler velocity of the antenna
``zupt``           zero velocity and zero angular rate while the vehicle stands still
``nhc``            the non-holonomic constraint of a ground vehicle
``odometry``       wheel odometry's forward speed with its scale factor
=================  ===========================================================================

:data:`REGISTRY` lists them; the estimators take the aids of a pass from :func:`ekf_aids` and
:func:`smoother_aids`, and the tuner its parameters from the registry. A new measurement is a new
module here with its ``AID`` added to :data:`REGISTRY` (and its reader and configuration keys).
"""

from __future__ import annotations

from . import gnss_accel, gnss_position, gnss_velocity, nhc, odometry, zupt
from .base import (  # noqa: F401 (the aids' vocabulary, re-exported)
    TAIL_P,
    AidSpec,
    EkfAid,
    EkfContext,
    Measurement,
    NodePrediction,
    SmootherAid,
    SmootherContext,
    tail_bound,
)

#: Every aid, in the order their update kinds are reported.
REGISTRY: tuple[AidSpec, ...] = (
    gnss_position.AID,
    gnss_accel.AID,
    gnss_velocity.AID,
    zupt.AID,
    nhc.AID,
    odometry.AID,
)
#: Update kinds, in the order they are reported.
KINDS = tuple(k for spec in REGISTRY for k in spec.kinds)
#: Method ids of each estimator and the variant of the aids each runs: the acceleration form it
#: applies (``None``: none; :data:`gnssacc.estimators.aids.gnss_accel.FORMS`).
EKF_METHODS = {"ekf": None} | {f"ekf-{s}": f for s, f in gnss_accel.FORMS.items()}
SMOOTHER_METHODS = {"smoother": None} | {f"smoother-{s}": f for s, f in gnss_accel.FORMS.items()}


def ekf_aids(ctx: EkfContext) -> list[EkfAid]:
    """The aids of an EKF pass (those the run and the settings have), named by their spec."""
    out = []
    for spec in REGISTRY:
        aid = spec.ekf(ctx)
        if aid is not None:
            aid.name = spec.name
            out.append(aid)
    return out


def smoother_aids(ctx: SmootherContext) -> list[SmootherAid]:
    """The aids of a smoother run, named by their spec, in the order their factors are added at
    a node."""
    out = []
    for spec in REGISTRY:
        aid = spec.smoother(ctx)
        if aid is not None:
            aid.name = spec.name
            out.append(aid)
    return sorted(out, key=lambda a: a.order)


def ekf_counts() -> dict:
    """Every aid's counters of an EKF pass, at zero."""
    return {k: v for spec in REGISTRY for k, v in spec.counts.items()}


def smoother_counts() -> dict:
    """Every aid's counters of a smoother run, at zero."""
    return {k: v for spec in REGISTRY for k, v in spec.smoother_counts.items()}
