"""From ``gnssacc batch``'s command line to a :class:`gnssacc.campaign.campaign.Campaign`: a new one, or
the one ``--resume`` names, whose stored settings the options given must not change, except to add
seeds, sources or outage patterns (:func:`gnssacc.campaign.campaign.grown`).

Every ``batch`` option defaults to ``None`` (not given), so that a resume can tell the options
given (compared with the campaign's settings) from those left out (taken from them).
"""

from __future__ import annotations

import json
from datetime import datetime

from .argcheck import check_source
from .argcheck import seeds as parse_seeds
from .campaign.campaign import (
    GROWABLE,
    OPTION_OF,
    Campaign,
    Pattern,
    differing_setting,
    full_bag,
    grown,
    make_settings,
)
from .core.errors import InputError, warn_data
from .pipeline import parse_methods
from .sources.simspec import is_sim_spec

#: ``gnssacc batch``'s bag options: setting -> argument (defaults: :data:`gnssacc.campaign.campaign.BAG_DEFAULTS`).
BAG_ARGUMENTS = {
    "imu_topic": "imu_topic",
    "gnss_topic": "gnss_topic",
    "truth_topic": "truth_topic",
    "time_source": "time_source",
    "gnss_from_truth_hz": "gnss_from_truth",
    "odom_topic": "odom_topic",
    "gnss": "gnss",
}
#: The outputs of a task folder when no option says otherwise.
DEFAULT_OUTPUTS = {"plots": True, "report": False, "export": []}


def campaign_from_args(args) -> Campaign:
    """The campaign to run (not yet entered, so not yet locked or created).

    Raises
    ------
    InputError
        A source is missing; or, with ``--resume``, no campaign there, or an option given (or
        the configuration file's content) differs from the campaign's settings.
    """
    if args.resume is None:
        settings = settings_from_args(args, {})
        _warn_if_seeds_do_nothing(settings)
        out = args.out or f"gnssacc-out/campaign-{datetime.now().strftime('%Y%m%d-%H%M%S')}"
        return Campaign.create(out, settings)
    camp = Campaign.open(args.resume)
    for _, path in camp.settings["sources"]:
        check_source(path)
    wanted = grown(camp.settings, settings_from_args(args, camp.settings))
    fixed = lambda d: {k: v for k, v in d.items() if k not in GROWABLE}
    key = differing_setting(fixed(camp.settings), fixed(wanted))
    if key is None and differing_setting(camp.settings, wanted) is not None:
        camp.grow(
            wanted
        )  # more seeds, sources or patterns: the campaign grows, its finished tasks stay
    if key is not None:
        raise InputError(
            "--resume",
            f"{camp.root} was started with other settings ({OPTION_OF[key]}: "
            f"{_short(camp.settings[key])} there, {_short(wanted[key])} now); resume "
            f"without changing them, or start a new campaign with --out",
        )
    return camp


def settings_from_args(args, stored: dict) -> dict:
    """The campaign settings from the arguments; what was not given comes from ``stored`` (a
    resumed campaign's settings), else from the defaults (:func:`gnssacc.campaign.campaign.make_settings`)."""

    def given(name, default):
        value = getattr(args, name)
        return value if value is not None else stored.get(name, default)

    before = full_bag(stored.get("bag"))
    bag = {
        k: getattr(args, a) if getattr(args, a) is not None else before[k]
        for k, a in BAG_ARGUMENTS.items()
    }
    out = stored.get("outputs", DEFAULT_OUTPUTS)
    patterns = (
        _patterns(args)
        if args.outage or args.outage_every
        else [Pattern(*p) for p in stored.get("outages", [[None, None]])]
    )
    return make_settings(
        args.sources or [p for _, p in stored.get("sources", [])],
        parse_methods(args.methods)
        if args.methods
        else stored.get("methods") or parse_methods(None),
        parse_seeds(args.seeds) if args.seeds else stored.get("seeds", [0]),
        patterns,
        noise=given("noise", None),
        preset=given("preset", None),
        tune=given("tune", None),
        config=args.config or (stored.get("config") or {}).get("path"),
        imu_frame=given("imu_frame", "frd"),
        bag=bag,
        plots=not args.no_plots if args.no_plots is not None else out["plots"],
        report=args.report if args.report is not None else out["report"],
        export=_exports(args.export) if args.export is not None else tuple(out["export"]),
    )


def _exports(values) -> tuple:
    """``--export``'s values (each a kind or a list of kinds, the option repeated) as kinds, once each."""
    return tuple(dict.fromkeys(k for v in values for k in ([v] if isinstance(v, str) else v)))


def _patterns(args) -> list[Pattern]:
    """The outage patterns of ``--outage`` (``none``: no outage) and ``--outage-every``, as given."""
    spans = [Pattern(None if o == "none" else o, None) for o in args.outage or []]
    return list(dict.fromkeys(spans + [Pattern(None, e) for e in args.outage_every or []]))


def _warn_if_seeds_do_nothing(settings: dict) -> None:
    """Several seeds change nothing for a recording with its own fixes and no ``--noise`` (the
    KITTI source and simulated runs draw their fixes, and a simulated run its IMU, from the seed)."""
    own = [name for name, path in settings["sources"] if path != "kitti" and not is_sim_spec(path)]
    if (
        len(settings["seeds"]) > 1
        and own
        and settings["noise"] is None
        and not settings["bag"]["gnss_from_truth_hz"]
    ):
        warn_data(
            "--seeds",
            f"without --noise, {own[0]}{' and the others' if len(own) > 1 else ''} keep their own "
            f"GNSS fixes, so every seed gives the same result there",
        )


def _short(value, limit: int = 60) -> str:
    text = json.dumps(value)
    return text if len(text) <= limit else text[: limit - 3] + "..."
