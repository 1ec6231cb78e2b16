"""One line on the ground-vehicle aids of a run: where the non-holonomic constraint was applied and
why not elsewhere, and how the wheel odometry was used (from the methods' ``stats`` in the
metrics, :mod:`gnssacc.estimators.aids.nhc`, :mod:`gnssacc.estimators.aids.odometry`)."""

from __future__ import annotations

from ..core.config import RunConfig


def _methods(metrics: dict) -> dict:
    """The methods that ran, without the smoothers' online twins (same factors)."""
    return {
        mid: m
        for mid, m in metrics["methods"].items()
        if m.get("status", "ok") == "ok" and not mid.endswith("-online")
    }


def _nhc_part(metrics: dict, cfg: RunConfig) -> str:
    c = cfg["nhc"]
    if not c["enabled"]:
        return "non-holonomic constraint off"
    cells = []
    for mid, m in _methods(metrics).items():
        st = m["stats"]
        n = st.get("n_nhc_updates", st.get("n_nhc_factors"))
        if n is None:
            continue
        cells.append(
            f"{mid} {n} ({st.get('n_nhc_skipped_rest', 0)} at rest, "
            f"{st.get('n_nhc_skipped_turn', 0)} turning on the spot)"
        )
    return (
        f"non-holonomic constraint (1-sigma lateral {float(c['sigma_lateral_mps']):.3g}, vertical "
        f"{float(c['sigma_vertical_mps']):.3g} m/s) applied at: " + ", ".join(cells)
    )


def _odometry_part(metrics: dict, cfg: RunConfig) -> str | None:
    cells = []
    for mid, m in _methods(metrics).items():
        st = m["stats"]
        n = st.get("n_odo_updates", st.get("n_odo_factors"))
        if not n:
            continue
        scale = st.get("odometry_scale")
        tail = (
            f", scale factor {100 * scale:+.2f} % +- {100 * st['odometry_scale_sigma']:.2f}"
            if scale is not None and st.get("odometry_scale_sigma") is not None
            else ""
        )
        cells.append(
            f"{mid} {n} samples ({st.get('n_odo_skipped_sign', 0)} refused for their sign{tail})"
        )
    if not cells:
        return None
    return (
        f"wheel odometry (1-sigma {float(cfg['odometry']['speed_sigma_mps']):.3g} m/s): "
        + ", ".join(cells)
    )


def aids_line(metrics: dict, cfg: RunConfig) -> str:
    """The line ``gnssacc run`` prints (``cfg``: the configuration the methods ran with)."""
    parts = [_nhc_part(metrics, cfg), _odometry_part(metrics, cfg)]
    return "; ".join(p for p in parts if p)
