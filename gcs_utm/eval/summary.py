"""What one fast-time run of a scenario says about the resolutions (:class:`ScenarioOutcome`),
and the summary of a set of runs (:class:`EvalSummary`: totals, one row per profile, one row
per scenario; JSON and markdown).

Definitions (pairs of UAS, judged on the simulated vehicles' true positions from take-off to
landing, under each pair's effective minima as Monitoring computes them: the report's
``truth``; on the UTM's tracks when there is no ground truth). Times are the run's seconds.
- *flown loss*: a pair whose true positions came inside its effective minima while both were
  airborne (whatever their plans said: after a plan has ended the vehicle is still traffic);
  it is reported with its minima and the horizontal / vertical distances at the instant of
  the smallest normalised separation;
- *predicted loss*: a pair for which Monitoring raised LOSS_OF_SEPARATION before the pair's
  first flown loss (any time, when it flew none);
- *avoided*: a predicted pair not flown as a loss; share avoided = avoided / predicted;
- *created by an accepted plan*: a flown loss while one of the pair flew a plan the UTM issued
  (its first verified upload before the loss), and not predicted before that upload;
- *missed*: any other flown loss that was not predicted before it happened;
- *geofence intrusion*: a UAS's true position inside an active geofence that applies to it,
  per UAS and geofence, with the time spent inside;
- *escalation without a command*: an escalation to the operator with no recommendation of its
  threat (of a UAS it names, when it names no threat) proposed within
  ``ESCALATION_COMMAND_WINDOW_S`` of it;
- *extra length / time* of an accepted plan: its 3D path length minus the previous plan's
  length from the new plan's start time on; its end time minus the previous plan's end time;
- *detection to recommendation / verified upload*: from the threat's detection to the
  recommendation's first proposal, and to its first ``applied: ... mission verified`` state
  change.
"""

from __future__ import annotations

import dataclasses
import itertools
import math
import re
import statistics
from collections.abc import Sequence
from dataclasses import dataclass

from gcs_utm.app.report import EscalationReport, PlanReport, RecommendationReport, Report
from gcs_utm.geo import LocalFrame

from .generator import PROFILES

Pair = tuple[str, str]

ESCALATION_COMMAND_WINDOW_S = 1.0
"""An escalation carries a proposed command when one is proposed this close to it (s)."""
TRACK_SAMPLE_PERIOD_S = 0.5
"""The period of the report's track samples (``gcs_utm.app.runner.SAMPLE_PERIOD_S``): an
intrusion seen on the tracks only lasts this long per sample inside."""
_PROFILE = re.compile(r"^enc_\d+_\d+_([a-z]+)_")


@dataclass(frozen=True, slots=True, kw_only=True)
class AcceptedPlan:
    uas: str
    version: int
    reason: str
    extra_length_m: float
    extra_time_s: float


@dataclass(frozen=True, slots=True, kw_only=True)
class FlownLoss:
    """A pair flown inside its effective minima (``minimum_*``). ``horizontal_m`` /
    ``vertical_m``: the distances at the instant of the smallest normalised separation
    ``min_ratio``; ``cause``: predicted (not avoided), created (by an accepted plan) or
    missed (never predicted before it happened)."""

    pair: Pair
    cause: str
    minimum_horizontal_m: float | None
    minimum_vertical_m: float | None
    horizontal_m: float | None
    vertical_m: float | None
    min_ratio: float | None
    first_loss_at_s: float | None
    duration_s: float


@dataclass(frozen=True, slots=True, kw_only=True)
class Intrusion:
    uas: str
    geofence: str
    first_at_s: float
    duration_s: float


@dataclass(frozen=True, slots=True, kw_only=True)
class ScenarioOutcome:
    """One scenario's run, reduced to what the evaluation counts. ``error`` names a run that
    did not complete (its counts are then empty). ``profile``: the generator profile of a
    generated encounter (from its name), else ``-``."""

    scenario: str
    wall_clock_s: float
    profile: str = "-"
    predicted_pairs: tuple[Pair, ...] = ()
    flown_loss_pairs: tuple[Pair, ...] = ()
    created_pairs: tuple[Pair, ...] = ()
    flown_losses: tuple[FlownLoss, ...] = ()
    geofence_intrusions: int = 0
    intrusions: tuple[Intrusion, ...] = ()
    escalations: int = 0
    escalations_without_command: int = 0
    accepted_plans: tuple[AcceptedPlan, ...] = ()
    detection_to_recommendation_s: tuple[float, ...] = ()
    detection_to_verified_upload_s: tuple[float, ...] = ()
    error: str = ""

    @property
    def predicted(self) -> int:
        return len(self.predicted_pairs)

    @property
    def flown_predicted(self) -> int:
        """Flown losses predicted before any plan the UTM issued to the pair (cause
        ``predicted``). Each flown loss has one cause: this + created + missed = flown."""
        return sum(f.cause == "predicted" for f in self.flown_losses)

    @property
    def avoided(self) -> int:
        """Predicted pairs not flown as a loss (a loss created by a plan made after an
        earlier prediction of the same pair is predicted and not avoided)."""
        return len(set(self.predicted_pairs) - set(self.flown_loss_pairs))

    @property
    def missed(self) -> int:
        """Flown losses not predicted before they happened and not created by a plan."""
        return sum(f.cause == "missed" for f in self.flown_losses)


def profile_of(scenario: str) -> str:
    """The generator profile in a generated encounter's name (``enc_S_NNNN_PROFILE_kind``)."""
    m = _PROFILE.match(scenario)
    if m and m.group(1) in PROFILES:
        return m.group(1)
    return "classic" if scenario.startswith("enc_") else "-"


def _pair(a: str, b: str) -> Pair:
    return (a, b) if a <= b else (b, a)


def _plan_length_m(frame: LocalFrame, plan: PlanReport, from_t_s: float) -> float:
    """3D length of ``plan`` from ``from_t_s`` (interpolated) to its end."""
    pts = []
    for w in plan.waypoints:
        e, n = frame.point_to_local(w[0], w[1])
        pts.append((e, n, w[2], w[3]))
    length = 0.0
    for p, q in itertools.pairwise(pts):
        if q[3] <= from_t_s:
            continue
        u = (from_t_s - p[3]) / (q[3] - p[3]) if p[3] < from_t_s else 0.0
        start = [p[k] + u * (q[k] - p[k]) for k in range(3)]
        length += math.dist(start, q[:3])
    return length


def _accepted_plans(report: Report, frame: LocalFrame) -> tuple[AcceptedPlan, ...]:
    out = []
    for op in report.operations:
        for prev, new in zip(op.plans, op.plans[1:], strict=False):
            if not new.waypoints or not prev.waypoints:
                continue
            t_start = new.waypoints[0][3]
            out.append(
                AcceptedPlan(
                    uas=op.id,
                    version=new.version,
                    reason=new.reason,
                    extra_length_m=round(
                        _plan_length_m(frame, new, t_start) - _plan_length_m(frame, prev, t_start),
                        2,
                    ),
                    extra_time_s=round(new.waypoints[-1][3] - prev.waypoints[-1][3], 3),
                )
            )
    return tuple(out)


def _proposed_at_s(history: Sequence[tuple[float | None, str]]) -> list[float]:
    """When each version of a recommendation was proposed."""
    return [t for t, text in history if t is not None and text.startswith("proposed")]


def _verified_at_s(history: Sequence[tuple[float | None, str]]) -> float | None:
    """When a version's mission was verified on the vehicle: the history's ``applied``
    state change whose reason is ``mission verified by readback``."""
    for t, text in history:
        if t is not None and "applied" in text and "mission verified" in text:
            return t
    return None


def _predicted_at(report: Report) -> dict[Pair, float]:
    """First detection time of each pair's LOSS_OF_SEPARATION (whenever raised: an aircraft
    whose plan has ended is still traffic)."""
    predicted_at: dict[Pair, float] = {}
    for t in report.threats:
        if t.kind != "LOSS_OF_SEPARATION" or len(t.uas) != 2 or t.detected_at_s is None:
            continue
        p = _pair(t.uas[0], t.uas[1])
        predicted_at[p] = min(predicted_at.get(p, math.inf), t.detected_at_s)
    return predicted_at


@dataclass(frozen=True, slots=True, kw_only=True)
class _Timings:
    applied_at: dict[str, list[float]]  # verified missions per UAS, in time order
    to_recommendation_s: tuple[float, ...]
    to_verified_upload_s: tuple[float, ...]


def _timings(report: Report) -> _Timings:
    applied_at: dict[str, list[float]] = {}
    to_rec: list[float] = []
    to_upload: list[float] = []
    for r in report.recommendations:
        verified = _verified_at_s(r.history)
        if verified is not None:
            applied_at.setdefault(r.uas, []).append(verified)
        detected = r.threat_detected_at_s
        if detected is None:
            continue
        proposed = _proposed_at_s(r.history)
        if proposed:
            to_rec.append(round(proposed[0] - detected, 3))
        if verified is not None:
            to_upload.append(round(verified - detected, 3))
    return _Timings(
        applied_at={u: sorted(ts) for u, ts in applied_at.items()},
        to_recommendation_s=tuple(to_rec),
        to_verified_upload_s=tuple(to_upload),
    )


def _flown(report: Report) -> list[FlownLoss]:
    """Flown losses (cause not yet decided), from the truth or else the tracks."""
    if report.truth is not None:
        return [
            FlownLoss(
                pair=_pair(*p.pair),
                cause="",
                minimum_horizontal_m=p.minimum_horizontal_m,
                minimum_vertical_m=p.minimum_vertical_m,
                horizontal_m=p.horizontal_at_closest_m,
                vertical_m=p.vertical_at_closest_m,
                min_ratio=p.min_ratio,
                first_loss_at_s=p.first_loss_at_s,
                duration_s=p.loss_duration_s,
            )
            for p in report.truth.pairs
            if p.loss_of_separation
        ]
    return [
        FlownLoss(
            pair=_pair(*s.pair),
            cause="",
            minimum_horizontal_m=s.minimum_horizontal_m,
            minimum_vertical_m=s.minimum_vertical_m,
            horizontal_m=s.horizontal_at_closest_m,
            vertical_m=s.vertical_at_closest_m,
            min_ratio=s.min_ratio,
            first_loss_at_s=None,
            duration_s=0.0,
        )
        for s in report.separation
        if s.loss_of_separation
    ]


def _cause(
    loss: FlownLoss, predicted_at: dict[Pair, float], applied: dict[str, list[float]]
) -> str:
    """predicted / created / missed (see the module doc)."""
    t_loss = math.inf if loss.first_loss_at_s is None else loss.first_loss_at_s
    t_pred = predicted_at.get(loss.pair, math.inf)
    first_apply = min(
        (t for u in loss.pair for t in applied.get(u, []) if t <= t_loss), default=math.inf
    )
    if math.isfinite(first_apply) and t_pred > first_apply:
        return "created"
    return "predicted" if t_pred < t_loss else "missed"


def _intrusions(report: Report) -> tuple[Intrusion, ...]:
    if report.truth is not None:
        return tuple(
            Intrusion(
                uas=g.uas, geofence=g.geofence, first_at_s=g.first_at_s, duration_s=g.duration_s
            )
            for g in report.truth.intrusions
        )
    return tuple(
        Intrusion(
            uas=g.uas,
            geofence=g.geofence,
            first_at_s=g.first_at_s,
            duration_s=g.samples_inside * TRACK_SAMPLE_PERIOD_S,
        )
        for g in report.geofence_intrusions
    )


def _without_command(report: Report) -> int:
    """Escalations with no recommendation proposed within ESCALATION_COMMAND_WINDOW_S of them
    for the threat they name (else the recommendation, else the UAS they name)."""
    threats = [t.id for t in report.threats]
    return sum(not _has_command(e, report.recommendations, threats) for e in report.escalations)


def _has_command(
    e: EscalationReport, recs: Sequence[RecommendationReport], threat_ids: Sequence[str]
) -> bool:
    if e.at_s is None:
        return True  # not placed in time: not judged
    named = [t for t in threat_ids if re.search(rf"(^|\W){re.escape(t)}(\W|$)", e.text)]
    if named:
        related = [r for r in recs if r.threat in named]
    else:
        related = [r for r in recs if re.search(rf"\b{re.escape(r.uas)}\b", e.text)]
    return any(
        abs(t - e.at_s) <= ESCALATION_COMMAND_WINDOW_S
        for r in related
        for t in _proposed_at_s(r.history)
    )


def outcome(report: Report) -> ScenarioOutcome:
    """Reduce a run report to the evaluation's counts."""
    frame = LocalFrame(
        report.origin.lat_deg, report.origin.lon_deg, report.origin.ground_elevation_amsl_m
    )
    predicted_at = _predicted_at(report)
    timings = _timings(report)
    flown = [
        dataclasses.replace(f, cause=_cause(f, predicted_at, timings.applied_at))
        for f in _flown(report)
    ]
    first_loss = {f.pair: f.first_loss_at_s for f in flown}
    predicted = sorted(
        p
        for p, t in predicted_at.items()
        if first_loss.get(p) is None or t < (first_loss[p] or math.inf)
    )
    intrusions = _intrusions(report)
    return ScenarioOutcome(
        scenario=report.scenario,
        profile=profile_of(report.scenario),
        wall_clock_s=report.wall_clock_s,
        predicted_pairs=tuple(predicted),
        flown_loss_pairs=tuple(sorted(f.pair for f in flown)),
        created_pairs=tuple(sorted(f.pair for f in flown if f.cause == "created")),
        flown_losses=tuple(sorted(flown, key=lambda f: f.pair)),
        geofence_intrusions=len(intrusions),
        intrusions=intrusions,
        escalations=len(report.escalations),
        escalations_without_command=_without_command(report),
        accepted_plans=_accepted_plans(report, frame),
        detection_to_recommendation_s=timings.to_recommendation_s,
        detection_to_verified_upload_s=timings.to_verified_upload_s,
    )


def _median(xs: Sequence[float]) -> float | None:
    return round(statistics.median(xs), 3) if xs else None


def _p95(xs: Sequence[float]) -> float | None:
    if not xs:
        return None
    s = sorted(xs)
    return round(s[min(len(s) - 1, math.ceil(0.95 * len(s)) - 1)], 3)


@dataclass(frozen=True, slots=True, kw_only=True)
class Totals:
    """The counts over a set of scenario runs (see the module doc for each definition)."""

    scenarios: int
    failed_runs: int
    predicted_losses: int
    losses_flown_under_effective_minima: int
    predicted_losses_flown: int
    losses_avoided: int
    share_avoided: float | None
    losses_created_by_accepted_plans: int
    losses_missed: int
    min_flown_horizontal_m: float | None  # at the closest normalised approach of a flown loss
    min_flown_vertical_m: float | None
    geofence_intrusions: int
    intrusion_time_s: float
    escalations: int
    escalations_without_command: int
    accepted_plans: int


@dataclass(frozen=True, slots=True, kw_only=True)
class ProfileSummary:
    profile: str
    totals: Totals
    wall_clock_s: float


@dataclass(frozen=True, slots=True, kw_only=True)
class EvalSummary:
    """Totals over a set of scenario runs, per profile, and per run. ``elapsed_wall_s``: the
    whole evaluation's wall time (parallel runs overlap; ``wall_clock_s`` sums the runs');
    ``encounters_per_minute`` = scenarios / elapsed minutes."""

    totals: Totals
    median_extra_length_m: float | None
    median_extra_time_s: float | None
    median_detection_to_recommendation_s: float | None
    p95_detection_to_recommendation_s: float | None
    median_detection_to_verified_upload_s: float | None
    p95_detection_to_verified_upload_s: float | None
    wall_clock_s: float
    elapsed_wall_s: float | None
    encounters_per_minute: float | None
    jobs: int | None
    profiles: tuple[ProfileSummary, ...]
    outcomes: tuple[ScenarioOutcome, ...]


def totals(outcomes: Sequence[ScenarioOutcome]) -> Totals:
    done = [o for o in outcomes if not o.error]
    predicted = sum(o.predicted for o in done)
    avoided = sum(o.avoided for o in done)
    flown = [f for o in done for f in o.flown_losses]
    hs = [f.horizontal_m for f in flown if f.horizontal_m is not None]
    vs = [f.vertical_m for f in flown if f.vertical_m is not None]
    return Totals(
        scenarios=len(outcomes),
        failed_runs=len(outcomes) - len(done),
        predicted_losses=predicted,
        losses_flown_under_effective_minima=sum(len(o.flown_loss_pairs) for o in done),
        predicted_losses_flown=sum(o.flown_predicted for o in done),
        losses_avoided=avoided,
        share_avoided=round(avoided / predicted, 4) if predicted else None,
        losses_created_by_accepted_plans=sum(len(o.created_pairs) for o in done),
        losses_missed=sum(o.missed for o in done),
        min_flown_horizontal_m=min(hs, default=None),
        min_flown_vertical_m=min(vs, default=None),
        geofence_intrusions=sum(o.geofence_intrusions for o in done),
        intrusion_time_s=round(sum(i.duration_s for o in done for i in o.intrusions), 3),
        escalations=sum(o.escalations for o in done),
        escalations_without_command=sum(o.escalations_without_command for o in done),
        accepted_plans=sum(len(o.accepted_plans) for o in done),
    )


def summarise(
    outcomes: Sequence[ScenarioOutcome],
    *,
    elapsed_wall_s: float | None = None,
    jobs: int | None = None,
) -> EvalSummary:
    done = [o for o in outcomes if not o.error]
    plans = [p for o in done for p in o.accepted_plans]
    to_rec = [x for o in done for x in o.detection_to_recommendation_s]
    to_up = [x for o in done for x in o.detection_to_verified_upload_s]
    by_profile: dict[str, list[ScenarioOutcome]] = {}
    for o in outcomes:
        by_profile.setdefault(o.profile, []).append(o)
    return EvalSummary(
        totals=totals(outcomes),
        median_extra_length_m=_median([p.extra_length_m for p in plans]),
        median_extra_time_s=_median([p.extra_time_s for p in plans]),
        median_detection_to_recommendation_s=_median(to_rec),
        p95_detection_to_recommendation_s=_p95(to_rec),
        median_detection_to_verified_upload_s=_median(to_up),
        p95_detection_to_verified_upload_s=_p95(to_up),
        wall_clock_s=round(sum(o.wall_clock_s for o in outcomes), 3),
        elapsed_wall_s=None if elapsed_wall_s is None else round(elapsed_wall_s, 3),
        encounters_per_minute=round(60.0 * len(outcomes) / elapsed_wall_s, 2)
        if elapsed_wall_s
        else None,
        jobs=jobs,
        profiles=tuple(
            ProfileSummary(
                profile=name,
                totals=totals(group),
                wall_clock_s=round(sum(o.wall_clock_s for o in group), 3),
            )
            for name, group in sorted(by_profile.items())
        ),
        outcomes=tuple(outcomes),
    )


def _fmt(x: float | None) -> str:
    return "-" if x is None else f"{x:g}"


def _share(t: Totals) -> str:
    return "-" if t.share_avoided is None else f"{100.0 * t.share_avoided:.1f} %"


def _closest(t: Totals) -> str:
    if t.min_flown_horizontal_m is None:
        return "-"
    return f"{t.min_flown_horizontal_m:g} / {_fmt(t.min_flown_vertical_m)} m"


def _total_lines(s: EvalSummary) -> list[str]:
    t = s.totals
    rate = "-" if s.encounters_per_minute is None else f"{s.encounters_per_minute:g}"
    return [
        "| measure | value |",
        "|---|---|",
        f"| scenarios (failed runs) | {t.scenarios} ({t.failed_runs}) |",
        f"| predicted losses of separation (pairs) | {t.predicted_losses} |",
        f"| predicted losses avoided | {t.losses_avoided} / {t.predicted_losses} ({_share(t)}) |",
        f"| losses flown under the effective minima | {t.losses_flown_under_effective_minima} |",
        f"| of which predicted before any UTM plan of the pair | {t.predicted_losses_flown} |",
        f"| of which created by accepted plans | {t.losses_created_by_accepted_plans} |",
        f"| of which never predicted | {t.losses_missed} |",
        f"| smallest flown horizontal / vertical distance | {_closest(t)} |",
        f"| geofence intrusions (time inside) | {t.geofence_intrusions} "
        f"({t.intrusion_time_s:g} s) |",
        f"| escalations (without a proposed command) | {t.escalations} "
        f"({t.escalations_without_command}) |",
        f"| accepted plans | {t.accepted_plans} |",
        f"| median extra length / time of an accepted plan | "
        f"{_fmt(s.median_extra_length_m)} m / {_fmt(s.median_extra_time_s)} s |",
        f"| detection to recommendation, median / p95 | "
        f"{_fmt(s.median_detection_to_recommendation_s)} / "
        f"{_fmt(s.p95_detection_to_recommendation_s)} s |",
        f"| detection to verified upload, median / p95 | "
        f"{_fmt(s.median_detection_to_verified_upload_s)} / "
        f"{_fmt(s.p95_detection_to_verified_upload_s)} s |",
        f"| wall clock, all runs | {s.wall_clock_s:.1f} s |",
        f"| elapsed (jobs), encounters per minute | {_fmt(s.elapsed_wall_s)} s "
        f"({s.jobs or '-'}), {rate} |",
    ]


def _profile_lines(s: EvalSummary) -> list[str]:
    lines = [
        "| profile | scenarios (failed) | predicted | avoided | flown losses | created | "
        "never predicted | smallest flown h / v | intrusions (s) | escalations (no command) "
        "| accepted plans |",
        "|---|---|---|---|---|---|---|---|---|---|---|",
    ]
    for p in s.profiles:
        t = p.totals
        lines.append(
            f"| {p.profile} | {t.scenarios} ({t.failed_runs}) | {t.predicted_losses} | "
            f"{t.losses_avoided} ({_share(t)}) | {t.losses_flown_under_effective_minima} | "
            f"{t.losses_created_by_accepted_plans} | {t.losses_missed} | {_closest(t)} | "
            f"{t.geofence_intrusions} ({t.intrusion_time_s:g}) | {t.escalations} "
            f"({t.escalations_without_command}) | {t.accepted_plans} |"
        )
    return lines


def _loss_text(f: FlownLoss) -> str:
    return (
        f"{f.pair[0]}-{f.pair[1]} {f.cause} {_fmt(f.horizontal_m)} / {_fmt(f.vertical_m)} m "
        f"(minima {_fmt(f.minimum_horizontal_m)} / {_fmt(f.minimum_vertical_m)})"
    )


def markdown(summary: EvalSummary) -> str:
    """The summary as markdown: totals, one row per profile, then one row per scenario."""
    s = summary
    lines = [*_total_lines(s), "", *_profile_lines(s), ""]
    lines += [
        "| scenario | predicted | flown losses | avoided | created | intrusions | "
        "escalations (no command) | accepted plans (extra m / s) | wall s |",
        "|---|---|---|---|---|---|---|---|---|",
    ]
    for o in s.outcomes:
        if o.error:
            lines.append(f"| {o.scenario} | run failed: {o.error} |||||||| ")
            continue
        plans = ", ".join(
            f"{p.uas} v{p.version} ({p.extra_length_m:+.0f} / {p.extra_time_s:+.0f})"
            for p in o.accepted_plans
        )
        losses = "; ".join(_loss_text(f) for f in o.flown_losses)
        fences = "; ".join(f"{i.uas} in {i.geofence} {i.duration_s:g} s" for i in o.intrusions)
        lines.append(
            f"| {o.scenario} | {o.predicted} | {len(o.flown_loss_pairs)}"
            f"{': ' + losses if losses else ''} | {o.avoided} | "
            f"{len(o.created_pairs)} | {o.geofence_intrusions}{': ' + fences if fences else ''} | "
            f"{o.escalations} ({o.escalations_without_command}) | "
            f"{plans or '-'} | {o.wall_clock_s:.1f} |"
        )
    return "\n".join(lines) + "\n"
