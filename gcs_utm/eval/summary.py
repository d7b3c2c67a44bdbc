"""What one fast-time run of a scenario says about the resolutions (:class:`ScenarioOutcome`),
and the summary of a set of runs (:class:`EvalSummary`, JSON and a markdown table).

Definitions (pairs of UAS, judged on the simulated vehicles' true positions and the effective
minima of each pair, as Monitoring judges; on the UTM's tracks when there is no ground truth):
- *predicted loss*: a pair for which Monitoring raised LOSS_OF_SEPARATION while both
  operations were in progress (an operation ends with its latest plan);
- *flown loss*: a pair that actually came closer than its minima;
- *avoided*: a predicted pair not flown as a loss; share avoided = avoided / predicted;
- *created by an accepted plan*: a flown loss of a pair with an applied plan of one of its UAS,
  first predicted after that plan was applied (or never);
- *missed*: any other flown loss that was never predicted;
- *extra length / time* of an accepted plan: its 3D path length minus the previous plan's
  length from the new plan's start time on; its end time minus the previous plan's end time;
- *detection to recommendation / verified upload*: from the threat's detection to the
  recommendation's first proposal, and to its first ``applied: ... mission verified`` state
  change.
"""

from __future__ import annotations

import itertools
import math
import statistics
from collections.abc import Sequence
from dataclasses import dataclass

from gcs_utm.app.report import PlanReport, Report
from gcs_utm.geo import LocalFrame

Pair = tuple[str, str]


@dataclass(frozen=True, slots=True, kw_only=True)
class AcceptedPlan:
    uas: str
    version: int
    reason: str
    extra_length_m: float
    extra_time_s: float


@dataclass(frozen=True, slots=True, kw_only=True)
class ScenarioOutcome:
    """One scenario's run, reduced to what the evaluation counts. ``error`` names a run that
    did not complete (its counts are then empty)."""

    scenario: str
    wall_clock_s: float
    predicted_pairs: tuple[Pair, ...] = ()
    flown_loss_pairs: tuple[Pair, ...] = ()
    created_pairs: tuple[Pair, ...] = ()
    geofence_intrusions: int = 0
    escalations: int = 0
    accepted_plans: tuple[AcceptedPlan, ...] = ()
    detection_to_recommendation_s: tuple[float, ...] = ()
    detection_to_verified_upload_s: tuple[float, ...] = ()
    error: str = ""

    @property
    def predicted(self) -> int:
        return len(self.predicted_pairs)

    @property
    def flown_predicted(self) -> int:
        """Predicted pairs flown as a loss anyway."""
        return len(set(self.predicted_pairs) & set(self.flown_loss_pairs))

    @property
    def avoided(self) -> int:
        return self.predicted - self.flown_predicted

    @property
    def missed(self) -> int:
        """Flown losses never predicted and not created by an accepted plan."""
        return len(set(self.flown_loss_pairs) - set(self.predicted_pairs) - set(self.created_pairs))


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


def _first_proposed_at_s(history: Sequence[tuple[float | None, str]]) -> float | None:
    """When the recommendation was first proposed (later versions re-plan the same threat)."""
    for t, text in history:
        if t is not None and text.startswith("proposed"):
            return t
    return None


def _verified_at_s(history: Sequence[tuple[float | None, str]]) -> float | None:
    """When a version's mission was verified on the vehicle: the history's ``applied``
    state change whose reason is ``mission verified by readback``."""
    for t, text in history:
        if t is not None and "applied" in text and "mission verified" in text:
            return t
    return None


def _predicted_at(report: Report) -> dict[Pair, float]:
    """First detection time of each pair's LOSS_OF_SEPARATION while both operations were in
    progress (an operation ends with its latest plan, as the report's ground truth does)."""
    ends = {op.id: op.plans[-1].waypoints[-1][3] for op in report.operations if op.plans}
    predicted_at: dict[Pair, float] = {}
    for t in report.threats:
        if t.kind != "LOSS_OF_SEPARATION" or len(t.uas) != 2 or t.detected_at_s is None:
            continue
        if t.detected_at_s >= min(ends.get(u, math.inf) for u in t.uas):
            continue  # raised after one of the two operations ended
        p = _pair(t.uas[0], t.uas[1])
        predicted_at[p] = min(predicted_at.get(p, math.inf), t.detected_at_s)
    return predicted_at


@dataclass(frozen=True, slots=True, kw_only=True)
class _Timings:
    applied_at: dict[str, float]  # first verified mission per UAS
    to_recommendation_s: tuple[float, ...]
    to_verified_upload_s: tuple[float, ...]


def _timings(report: Report) -> _Timings:
    applied_at: dict[str, float] = {}
    to_rec: list[float] = []
    to_upload: list[float] = []
    for r in report.recommendations:
        verified = _verified_at_s(r.history)
        if verified is not None:
            applied_at[r.uas] = min(applied_at.get(r.uas, math.inf), verified)
        detected = r.threat_detected_at_s
        if detected is None:
            continue
        proposed = _first_proposed_at_s(r.history)
        if proposed is not None:
            to_rec.append(round(proposed - detected, 3))
        if verified is not None:
            to_upload.append(round(verified - detected, 3))
    return _Timings(
        applied_at=applied_at,
        to_recommendation_s=tuple(to_rec),
        to_verified_upload_s=tuple(to_upload),
    )


def outcome(report: Report) -> ScenarioOutcome:
    """Reduce a run report to the evaluation's counts."""
    frame = LocalFrame(
        report.origin.lat_deg, report.origin.lon_deg, report.origin.ground_elevation_amsl_m
    )
    predicted_at = _predicted_at(report)
    if report.truth is not None:
        flown = {_pair(*p.pair) for p in report.truth.pairs if p.loss_of_separation}
    else:
        flown = {_pair(*s.pair) for s in report.separation if s.loss_of_separation}
    timings = _timings(report)
    created = set()
    for p in flown:
        applied = timings.applied_at
        first_apply = min(applied.get(p[0], math.inf), applied.get(p[1], math.inf))
        if math.isfinite(first_apply) and predicted_at.get(p, math.inf) > first_apply:
            created.add(p)
    return ScenarioOutcome(
        scenario=report.scenario,
        wall_clock_s=report.wall_clock_s,
        predicted_pairs=tuple(sorted(predicted_at)),
        flown_loss_pairs=tuple(sorted(flown)),
        created_pairs=tuple(sorted(created)),
        geofence_intrusions=len(report.geofence_intrusions),
        escalations=len(report.escalations),
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
class EvalSummary:
    """Totals over a set of scenario runs (see the module doc for each definition)."""

    scenarios: int
    failed_runs: int
    predicted_losses: int
    losses_flown_under_effective_minima: int
    predicted_losses_flown: int
    losses_avoided: int
    share_avoided: float | None
    losses_created_by_accepted_plans: int
    losses_missed: int
    geofence_intrusions: int
    escalations: int
    accepted_plans: int
    median_extra_length_m: float | None
    median_extra_time_s: float | None
    median_detection_to_recommendation_s: float | None
    p95_detection_to_recommendation_s: float | None
    median_detection_to_verified_upload_s: float | None
    p95_detection_to_verified_upload_s: float | None
    wall_clock_s: float
    outcomes: tuple[ScenarioOutcome, ...]


def summarise(outcomes: Sequence[ScenarioOutcome]) -> EvalSummary:
    done = [o for o in outcomes if not o.error]
    predicted = sum(o.predicted for o in done)
    avoided = sum(o.avoided for o in done)
    plans = [p for o in done for p in o.accepted_plans]
    to_rec = [x for o in done for x in o.detection_to_recommendation_s]
    to_up = [x for o in done for x in o.detection_to_verified_upload_s]
    return EvalSummary(
        scenarios=len(outcomes),
        failed_runs=len(outcomes) - len(done),
        predicted_losses=predicted,
        losses_flown_under_effective_minima=sum(len(o.flown_loss_pairs) for o in done),
        predicted_losses_flown=sum(o.flown_predicted for o in done),
        losses_avoided=avoided,
        share_avoided=round(avoided / predicted, 4) if predicted else None,
        losses_created_by_accepted_plans=sum(len(o.created_pairs) for o in done),
        losses_missed=sum(o.missed for o in done),
        geofence_intrusions=sum(o.geofence_intrusions for o in done),
        escalations=sum(o.escalations for o in done),
        accepted_plans=len(plans),
        median_extra_length_m=_median([p.extra_length_m for p in plans]),
        median_extra_time_s=_median([p.extra_time_s for p in plans]),
        median_detection_to_recommendation_s=_median(to_rec),
        p95_detection_to_recommendation_s=_p95(to_rec),
        median_detection_to_verified_upload_s=_median(to_up),
        p95_detection_to_verified_upload_s=_p95(to_up),
        wall_clock_s=round(sum(o.wall_clock_s for o in outcomes), 3),
        outcomes=tuple(outcomes),
    )


def _fmt(x: float | None) -> str:
    return "-" if x is None else f"{x:g}"


def markdown(summary: EvalSummary) -> str:
    """The summary as markdown: totals, then one row per scenario."""
    s = summary
    share = "-" if s.share_avoided is None else f"{100.0 * s.share_avoided:.1f} %"
    lines = [
        "| measure | value |",
        "|---|---|",
        f"| scenarios (failed runs) | {s.scenarios} ({s.failed_runs}) |",
        f"| predicted losses of separation (pairs) | {s.predicted_losses} |",
        f"| losses flown under the effective minima | {s.losses_flown_under_effective_minima} |",
        f"| predicted losses avoided | {s.losses_avoided} ({share}) |",
        f"| losses created by accepted plans | {s.losses_created_by_accepted_plans} |",
        f"| losses never predicted | {s.losses_missed} |",
        f"| geofence intrusions | {s.geofence_intrusions} |",
        f"| escalations | {s.escalations} |",
        f"| accepted plans | {s.accepted_plans} |",
        f"| median extra length / time of an accepted plan | "
        f"{_fmt(s.median_extra_length_m)} m / {_fmt(s.median_extra_time_s)} s |",
        f"| detection to recommendation, median / p95 | "
        f"{_fmt(s.median_detection_to_recommendation_s)} / "
        f"{_fmt(s.p95_detection_to_recommendation_s)} s |",
        f"| detection to verified upload, median / p95 | "
        f"{_fmt(s.median_detection_to_verified_upload_s)} / "
        f"{_fmt(s.p95_detection_to_verified_upload_s)} s |",
        f"| wall clock, all runs | {s.wall_clock_s:.1f} s |",
        "",
        "| scenario | predicted | flown losses | avoided | created | intrusions | "
        "escalations | accepted plans (extra m / s) | wall s |",
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
        lines.append(
            f"| {o.scenario} | {o.predicted} | {len(o.flown_loss_pairs)} | {o.avoided} | "
            f"{len(o.created_pairs)} | {o.geofence_intrusions} | {o.escalations} | "
            f"{plans or '-'} | {o.wall_clock_s:.1f} |"
        )
    return "\n".join(lines) + "\n"
