"""``gcs-utm scenario check FILE [--yaml Y] [--json] [--apply-delays]``: validate a scenario
(our TOML, or a GAUSS JSON with its YAML), summarise it and run the strategic check of the
filed plans: every pair already in conflict, every plan crossing a geofence.

Times are printed in scenario seconds (relative to its start). Exit 0 when the file is valid
(conflicts are findings, not errors), 2 when it is not (one error line on stderr; with
``--json`` also one JSON document on stdout: ``{"error": {"file", "item", "field",
"message"}}``). FILE may also be a GAUSS scenario YAML: it loads the scenario it names.
"""

from __future__ import annotations

import argparse
import json
import math
import sys
from dataclasses import replace
from typing import Any, TextIO

from gcs_utm.core.monitoring.config import MonitoringConfig
from gcs_utm.core.monitoring.strategic import StrategicReport, strategic_check
from gcs_utm.model import Operation
from gcs_utm.scenario import Scenario, ScenarioError, load_any


def register(sub: argparse._SubParsersAction[argparse.ArgumentParser]) -> None:
    p = sub.add_parser("scenario", help="scenario tools")
    cmds = p.add_subparsers(dest="scenario_command", metavar="ACTION", required=True)
    c = cmds.add_parser("check", help="validate a scenario and check its filed plans")
    c.add_argument(
        "file", help="scenario TOML, a GAUSS operations/geofences JSON, or a GAUSS scenario YAML"
    )
    c.add_argument("--yaml", help="GAUSS YAML with the origin (default: FILE with .yaml)")
    c.add_argument("--json", action="store_true", help="print one JSON document")
    c.add_argument(
        "--apply-delays",
        action="store_true",
        help="shift each plan by its vehicle's start_delay_s before checking (as flown)",
    )
    c.add_argument(
        "--step-s",
        default="1.0",
        help=f"sampling step of the check, at least {MIN_STEP_S:g} s (default 1 s)",
    )
    c.set_defaults(func=_check)


MIN_STEP_S = 0.01
"""Finer than any vehicle's position stream (50 Hz is 20 ms); a smaller step only multiplies
the samples the check holds in memory."""


def delayed_operations(scenario: Scenario) -> list[Operation]:
    """The operations with every plan time shifted by the vehicle's start delay."""
    out = []
    for op in scenario.operations:
        delay = scenario.vehicle(op.id).start_delay_s
        wps = tuple(replace(w, t_s=w.t_s + delay) for w in op.plan.waypoints)
        out.append(replace(op, plan=replace(op.plan, waypoints=wps)))
    return out


def report_document(scenario: Scenario, report: StrategicReport) -> dict[str, Any]:
    t0 = scenario.t0_s
    config = scenario.monitoring_for(MonitoringConfig())
    return {
        "scenario": scenario.name,
        "source": scenario.source,
        "duration_s": scenario.duration_s,
        "separation": {
            "mode": config.separation_mode,
            "safety_distance_m": config.safety_distance_m if config.spherical else None,
            "horizontal_m": None if config.spherical else config.separation_horizontal_m,
            "vertical_m": None if config.spherical else config.separation_vertical_m,
        },
        "origin": {
            "lat_deg": scenario.frame.origin_lat_deg,
            "lon_deg": scenario.frame.origin_lon_deg,
            "ground_elevation_amsl_m": scenario.frame.ground_elevation_amsl_m,
        },
        "operations": [
            {
                "id": op.id,
                "priority": op.priority,
                "vehicle": op.vehicle_kind.value,
                "autopilot": op.autopilot.value,
                "cruise_speed_mps": op.cruise_speed_mps,
                "waypoints": len(op.plan.waypoints),
                "start_s": op.plan.start_t_s - t0,
                "end_s": op.plan.end_t_s - t0,
                "start_delay_s": scenario.vehicle(op.id).start_delay_s,
            }
            for op in scenario.operations
        ],
        "geofences": [
            {
                "id": g.id,
                "shape": g.shape.value,
                "kind": g.kind.value,
                "min_alt_amsl_m": g.min_alt_amsl_m,
                "max_alt_amsl_m": g.max_alt_amsl_m,
                "reason": g.reason,
            }
            for g in scenario.geofences
        ],
        "events": [
            {"at_s": e.at_s, "kind": e.kind.value, "uas": e.uas, "reason": e.reason}
            for e in scenario.events
        ],
        "conflicts": [
            {
                "a": c.a,
                "b": c.b,
                "first_loss_s": c.first_loss_t_s - t0,
                "closest_s": c.closest_t_s - t0,
                "min_distance_m": c.min_distance_m,
                "min_horizontal_m": c.min_horizontal_m,
                "min_vertical_m": c.min_vertical_m,
            }
            for c in report.conflicts
        ],
        "crossings": [
            {"operation": x.operation_id, "geofence": x.geofence_id, "entry_s": x.entry_t_s - t0}
            for x in report.crossings
        ],
    }


_LINES_PER_WRITE = 1000


def write_json(doc: dict[str, Any], out: TextIO) -> None:
    """``doc`` as one JSON document: a top-level key per line, each element of a list on a
    line of its own, written in chunks as it goes (a dense airspace's report holds tens of
    thousands of conflicts: one ``json.dump`` of it with an indent took seconds)."""
    out.write("{\n")
    last = len(doc) - 1
    for n, (key, value) in enumerate(doc.items()):
        comma = "," if n < last else ""
        if not isinstance(value, list) or not value:
            out.write(f"  {json.dumps(key)}: {json.dumps(value)}{comma}\n")
            continue
        out.write(f"  {json.dumps(key)}: [\n")
        for start in range(0, len(value), _LINES_PER_WRITE):
            chunk = value[start : start + _LINES_PER_WRITE]
            more = "," if start + _LINES_PER_WRITE < len(value) else ""
            out.write("    " + ",\n    ".join(map(json.dumps, chunk)) + more + "\n")
        out.write(f"  ]{comma}\n")
    out.write("}\n")


def _fail(args: argparse.Namespace, error: dict[str, str]) -> int:
    """One error line on stderr; with --json also the error as a JSON document on stdout."""
    where = ": ".join(v for v in (error["file"], error["item"], error["field"]) if v)
    print(f"error: {where}: {error['message']}", file=sys.stderr)
    if args.json:
        json.dump({"error": error}, sys.stdout, indent=2)
        sys.stdout.write("\n")
    return 2


def _step_s(text: str) -> float | None:
    try:
        value = float(text)
    except ValueError:
        return None
    return value if MIN_STEP_S <= value < math.inf else None


def _check(args: argparse.Namespace) -> int:
    try:
        return _check_file(args)
    except Exception as exc:
        # a bug, not bad input: the --json reader still gets its document, the traceback
        # goes to stderr
        if args.json:
            error = {"file": args.file, "item": "", "field": "", "message": f"internal: {exc!r}"}
            json.dump({"error": error}, sys.stdout, indent=2)
            sys.stdout.write("\n")
        raise


def _check_file(args: argparse.Namespace) -> int:
    step_s = _step_s(args.step_s)
    if step_s is None:
        message = f"expected a number of seconds >= {MIN_STEP_S:g}, got {args.step_s!r}"
        return _fail(args, {"file": "", "item": "", "field": "--step-s", "message": message})
    try:
        scenario = load_any(args.file, args.yaml)
    except ScenarioError as exc:
        field = "" if exc.field == exc.item else exc.field
        return _fail(
            args, {"file": exc.file, "item": exc.item, "field": field, "message": exc.message}
        )
    ops = delayed_operations(scenario) if args.apply_delays else list(scenario.operations)
    config = scenario.monitoring_for(MonitoringConfig())
    report = strategic_check(ops, scenario.geofences, scenario.frame, config, step_s=step_s)
    doc = report_document(scenario, report)
    if args.json:
        write_json(doc, sys.stdout)
        return 0
    _print(args, scenario, doc)
    return 0


def _print(args: argparse.Namespace, scenario: Scenario, doc: dict[str, Any]) -> None:
    out = sys.stdout
    out.write(f"{scenario.name} ({scenario.source}): valid, {scenario.duration_s:.0f} s\n")
    out.write(f"  {len(doc['operations'])} operations:\n")
    for o in doc["operations"]:
        out.write(
            f"    {o['id']}: {o['vehicle']} {o['autopilot']}, priority {o['priority']}, "
            f"{o['cruise_speed_mps']:.1f} m/s, {o['waypoints']} waypoints, "
            f"t {o['start_s']:.0f}..{o['end_s']:.0f} s, start delay {o['start_delay_s']:g} s\n"
        )
    out.write(f"  {len(doc['geofences'])} geofences\n")
    for g in doc["geofences"]:
        out.write(f"    {g['id']}: {g['shape']} {g['kind']} {g['reason']}\n")
    out.write(f"  {len(doc['events'])} events\n")
    for e in doc["events"]:
        out.write(f"    t={e['at_s']:g} s {e['kind']} {e['uas'] or ''}\n")
    label = "as flown (start delays applied)" if args.apply_delays else "as filed"
    if not doc["conflicts"] and not doc["crossings"]:
        out.write(f"  strategic check {label}: no conflicts, no geofence crossings\n")
    for c in doc["conflicts"]:
        out.write(
            f"  CONFLICT {label}: {c['a']} x {c['b']}: first loss at t={c['first_loss_s']:.1f} s,"
            f" closest {c['min_distance_m']:.1f} m at t={c['closest_s']:.1f} s\n"
        )
    for x in doc["crossings"]:
        out.write(
            f"  GEOFENCE {label}: {x['operation']} enters {x['geofence']}"
            f" at t={x['entry_s']:.1f} s\n"
        )
