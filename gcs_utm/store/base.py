"""The typed store API over any SQL backend (SQLite or PostgreSQL), one connection.

Invariants (for every backend):
- each public write method is one transaction (or one SAVEPOINT inside the writer thread's
  batch transaction, see :mod:`gcs_utm.store.writer`), so a failure leaves nothing half-written;
- documents are the model objects as JSON (:mod:`gcs_utm.store.codec`); the columns beside them
  exist only to select and order rows;
- the SQL here is the common dialect of SQLite and PostgreSQL (``?`` placeholders, which the
  PostgreSQL connection translates; ``ON CONFLICT ... DO UPDATE ... WHERE``; ``RETURNING``).

A backend (:class:`gcs_utm.store.sqlite.Store`, :class:`gcs_utm.store.postgres.PgStore`)
opens the connection, applies the migrations and says how a transaction begins; everything
else is here, so both backends write the same rows with the same semantics.
"""

from __future__ import annotations

import contextlib
import dataclasses
import json
import operator
import os
import time
import types
import typing
from collections.abc import Callable, Iterator, Sequence
from typing import Any, Protocol

from gcs_utm.messages import PilotAnswer
from gcs_utm.model import (
    AuditEntry,
    FlightPlan,
    Geofence,
    GeofenceId,
    Operation,
    OperationId,
    Recommendation,
    RecommendationState,
    RemoteIdentity,
    Threat,
    ThreatStatus,
    Track,
    TrackId,
    Waypoint4D,
)
from gcs_utm.store.codec import CodecError, dumps, loads


class StoreError(RuntimeError):
    """The database cannot be used (newer schema, corrupt document, closed store, lost
    connection)."""


class FencedError(StoreError):
    """A write of a row owned by an operation's region, refused because the writing life's
    lease of that region was taken over since (a cluster member that stalled past its lease
    expiry, see :mod:`gcs_utm.cluster.fence`)."""


class Cursor(Protocol):
    """What a statement returns, on either backend."""

    @property
    def rowcount(self) -> int: ...

    def fetchone(self) -> Any: ...

    def fetchall(self) -> list[Any]: ...


class Connection(Protocol):
    """The one call the typed API makes on a backend's connection: SQL with ``?``
    placeholders."""

    def execute(self, sql: str, params: Sequence[Any] = ..., /) -> Any: ...


def _flat_fields(cls: type, skip: str) -> tuple[str, ...] | None:
    """The field names of dataclass ``cls`` but the last, ``skip``, when each is annotated as
    a JSON scalar (str, float, int, bool, a NewType of one, optional) or a tuple of floats,
    else None."""
    scalars = (str, float, int, bool, type(None))

    def flat(tp: Any) -> bool:
        tp = getattr(tp, "__supertype__", tp)  # NewType
        if tp in scalars:
            return True
        args = typing.get_args(tp)
        if typing.get_origin(tp) is tuple:
            return all(a is float for a in args)
        if typing.get_origin(tp) in (types.UnionType, typing.Union):
            return all(flat(a) for a in args)
        return False

    hints = typing.get_type_hints(cls)
    names = tuple(f.name for f in dataclasses.fields(cls))
    if names[-1:] != (skip,):
        return None
    names = names[:-1]
    return names if all(flat(hints[n]) for n in names) else None


# remote_id (a nested record, None on most tracks) is left to the generic path when it is set
_TRACK_FIELDS = _flat_fields(Track, skip="remote_id")
_track_values = operator.attrgetter(*_TRACK_FIELDS) if _TRACK_FIELDS else None
_TRACK_KEYS = (*(_TRACK_FIELDS or ()), "remote_id")


def track_doc(t: Track) -> str:
    """``dumps(t)``, about three times faster: the store's writer thread writes every updated
    track once a second, holding the GIL while it encodes. While every Track field is a JSON
    scalar or a tuple of floats (checked on the annotations at import), ``json.dumps`` of the
    fields writes exactly the generic codec's :func:`encode` form (a tuple is an array); a
    value of another type at run time (a NumPy integer, say) takes the generic path."""
    if _track_values is None or _TRACK_FIELDS is None or t.remote_id is not None:
        return dumps(t)
    try:
        return json.dumps(
            dict(zip(_TRACK_KEYS, (*_track_values(t), None), strict=True)),
            separators=(",", ":"),
            allow_nan=True,
        )
    except TypeError:
        return dumps(t)


class StoreBase:
    """Typed access to one database; a backend subclass opens ``self._conn``, migrates it and
    sets ``where`` (what error messages name), ``readonly`` and ``max_params``."""

    where: str
    readonly: bool
    max_params: int
    _conn: Any
    # how a top-level transaction begins (SQLite: take the write lock at once)
    _begin_sql = "BEGIN"
    # A cluster member's lease fence (gcs_utm.cluster.fence): called with the connection and
    # the operation id inside the transaction of every write of a row its region owns (the
    # operation, its plans, its recommendations); raises FencedError to refuse the write.
    fence: Callable[[Connection, str], None] | None = None

    def _init_state(self) -> None:
        self._depth = 0
        self._epoch: int | None = None

    # ---- lifecycle ----------------------------------------------------------------------
    # the database's clock in POSIX seconds (leases expire on it, not on an instance's clock)
    _now_sql = ""

    def now_unix_s(self) -> float:
        """The database server's wall clock, POSIX seconds: one clock for every instance."""
        return float(self._conn.execute(self._now_sql).fetchone()[0])

    def ping(self) -> None:
        """One round trip on the connection (raises :class:`StoreError` when it is lost)."""
        self._conn.execute("SELECT 1").fetchone()

    def close(self) -> None:
        self._conn.close()

    def __enter__(self) -> typing.Self:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()

    def begin_life(self, started_unix_s: float | None = None) -> int:
        """Begin a new life of this store (one process writing decisions) and return its
        epoch: 1, 2, 3, ... never reused (SQLite's AUTOINCREMENT and PostgreSQL's identity
        sequence never hand out a number twice, even after the row is gone). Ids made in this
        life carry the epoch (see :func:`gcs_utm.store.ids.life_prefix`), and rows written in
        it are tagged with it."""
        if self.readonly:
            raise StoreError(f"{self.where}: a read-only store has no life")
        with self.transaction() as c:
            cur = c.execute(
                "INSERT INTO lives (started_unix_s, pid) VALUES (?, ?) RETURNING epoch",
                (time.time() if started_unix_s is None else started_unix_s, os.getpid()),
            )
            self._epoch = int(cur.fetchone()[0])
        return self._epoch

    @property
    def epoch(self) -> int:
        """The epoch of this store's life; the first write of a threat or recommendation
        begins one when the owner has not."""
        if self._epoch is None:
            return self.begin_life()
        return self._epoch

    def mark_batch(self, c: Connection, epoch: int, batch: int) -> None:
        """Record, inside a batch's transaction, that life ``epoch``'s batch ``batch`` commits
        with it (the writer numbers its batches 1, 2, ... in order)."""
        c.execute("UPDATE lives SET committed_batch = ? WHERE epoch = ?", (batch, epoch))

    def committed_batch(self, epoch: int) -> int:
        """The number of the last batch life ``epoch`` committed (0: none)."""
        row = self._conn.execute(
            "SELECT committed_batch FROM lives WHERE epoch = ?", (epoch,)
        ).fetchone()
        return 0 if row is None else int(row[0])

    def lives(self) -> list[tuple[int, float, int]]:
        """(epoch, started_unix_s, pid) of every life, oldest first."""
        return [
            (int(e), float(t), int(p))
            for e, t, p in self._rows("SELECT epoch, started_unix_s, pid FROM lives ORDER BY epoch")
        ]

    @contextlib.contextmanager
    def transaction(self) -> Iterator[Connection]:
        """One transaction; nested calls become savepoints, so an inner failure rolls back
        only its own writes."""
        conn = self._conn
        if self._depth == 0:
            conn.execute(self._begin_sql)
            commit, rollback = "COMMIT", "ROLLBACK"
        else:
            name = f"sp{self._depth}"
            commit, rollback = f"RELEASE {name}", f"ROLLBACK TO {name}"
            conn.execute(f"SAVEPOINT {name}")
        self._depth += 1
        try:
            yield conn
        except BaseException:
            self._depth -= 1
            self._undo(rollback, commit)
            raise
        self._depth -= 1
        conn.execute(commit)

    def _undo(self, rollback: str, release: str) -> None:
        """Roll back after a failure; a connection that cannot even do that is left to the
        caller's exception (the original error matters more than this one)."""
        with contextlib.suppress(Exception):
            self._conn.execute(rollback)
            if self._depth > 0:
                self._conn.execute(release)  # ROLLBACK TO keeps the savepoint open: close it

    def lock_key(self, c: Connection, key: str) -> None:
        """Serialise the transactions that call this with the same ``key`` until they end
        (SQLite: its one writer already does; PostgreSQL: a transaction advisory lock)."""
        return None

    def _fenced(self, c: Connection, op_id: str) -> None:
        if self.fence is not None:
            self.fence(c, op_id)

    def _rows(self, sql: str, params: Sequence[Any] = ()) -> list[tuple[Any, ...]]:
        return list(self._conn.execute(sql, params).fetchall())

    # ---- operations and plans -----------------------------------------------------------
    def save_operation(self, op: Operation, t_s: float | None = None) -> None:
        """Insert or update an operation; its current plan is also kept as a plan version."""
        with self.transaction() as c:
            self._fenced(c, op.id)
            c.execute(
                "INSERT INTO operations (id, state, updated_t_s, doc) VALUES (?, ?, ?, ?) "
                "ON CONFLICT(id) DO UPDATE SET state=excluded.state, "
                "updated_t_s=excluded.updated_t_s, doc=excluded.doc",
                (op.id, op.state.value, op.plan.created_t_s if t_s is None else t_s, dumps(op)),
            )
            self.save_plan(op.plan)

    def load_operations(self) -> list[Operation]:
        return [
            self._load(Operation, d)
            for (d,) in self._rows("SELECT doc FROM operations ORDER BY id")
        ]

    def save_plan(self, plan: FlightPlan) -> None:
        """Keep a plan version. A version is immutable: saving a different plan under an
        existing (operation, version) raises :class:`StoreError`."""
        waypoints = dumps(plan.waypoints)
        with self.transaction() as c:
            self._fenced(c, plan.operation_id)
            row = c.execute(
                "SELECT waypoints, reason, created_t_s FROM flight_plans "
                "WHERE operation_id=? AND version=?",
                (plan.operation_id, plan.version),
            ).fetchone()
            if row is not None:
                if self._plan_from(plan.operation_id, plan.version, row[2], row[1], row[0]) != plan:
                    raise StoreError(
                        f"plan {plan.operation_id} version {plan.version} exists with other content"
                    )
                return
            c.execute(
                "INSERT INTO flight_plans VALUES (?, ?, ?, ?, ?, ?, ?)",
                (
                    plan.operation_id,
                    plan.version,
                    plan.created_t_s,
                    plan.reason,
                    plan.start_t_s,
                    plan.end_t_s,
                    waypoints,
                ),
            )

    def _plan_from(
        self, op_id: str, version: int, created: float, reason: str, wps: str
    ) -> FlightPlan:
        return FlightPlan(
            operation_id=OperationId(op_id),
            version=version,
            waypoints=self._load(tuple[Waypoint4D, ...], wps),
            created_t_s=created,
            reason=reason,
        )

    def load_plans(self, op_id: str) -> list[FlightPlan]:
        """Every version of an operation's plan, oldest first."""
        return [
            self._plan_from(op_id, v, c, r, w)
            for v, c, r, w in self._rows(
                "SELECT version, created_t_s, reason, waypoints FROM flight_plans "
                "WHERE operation_id=? ORDER BY version",
                (op_id,),
            )
        ]

    def latest_plan(self, op_id: str) -> FlightPlan | None:
        rows = self._rows(
            "SELECT version, created_t_s, reason, waypoints FROM flight_plans "
            "WHERE operation_id=? ORDER BY version DESC LIMIT 1",
            (op_id,),
        )
        return self._plan_from(op_id, *rows[0]) if rows else None

    # ---- geofences ----------------------------------------------------------------------
    def save_geofence(self, fence: Geofence, *, active: bool = True) -> None:
        with self.transaction() as c:
            c.execute(
                "INSERT INTO geofences (id, active, start_t_s, end_t_s, doc) "
                "VALUES (?, ?, ?, ?, ?) "
                "ON CONFLICT(id) DO UPDATE SET active=excluded.active, "
                "start_t_s=excluded.start_t_s, end_t_s=excluded.end_t_s, doc=excluded.doc",
                (fence.id, int(active), fence.start_t_s, fence.end_t_s, dumps(fence)),
            )

    def deactivate_geofence(self, fence_id: GeofenceId | str) -> bool:
        """Mark a geofence inactive (kept for the record). False if there is no such id."""
        with self.transaction() as c:
            cur = c.execute("UPDATE geofences SET active=0 WHERE id=?", (fence_id,))
            return bool(cur.rowcount > 0)

    def load_geofences(self, *, active_only: bool = True) -> list[Geofence]:
        where = " WHERE active=1" if active_only else ""
        return [
            self._load(Geofence, d)
            for (d,) in self._rows(f"SELECT doc FROM geofences{where} ORDER BY id")
        ]

    # ---- tracks -------------------------------------------------------------------------
    def write_tracks(self, tracks: Sequence[Track]) -> None:
        """Latest state and history of each track, in one transaction. An older sample never
        replaces a newer latest state (history keeps everything)."""
        if not tracks:
            return
        docs = [(t, track_doc(t)) for t in tracks]
        # The newest sample of each id (the later one of equal times), as writing the samples
        # one by one leaves it: one upsert row per id, because PostgreSQL refuses a statement
        # that updates the same row twice.
        newest: dict[str, tuple[Track, str]] = {}
        for t, d in docs:
            seen = newest.get(t.id)
            if seen is None or t.t_s >= seen[0].t_s:
                newest[t.id] = (t, d)
        latest = list(newest.values())
        # Multi-row statements, not executemany: the sqlite3 module releases and retakes the
        # GIL around every statement step, and the event loop then had to hand the GIL over
        # twice per row (a thousand tracks a second cost the loop ~5-10 us per message); a
        # PostgreSQL round trip per row would cost more still.
        per = max(1, min(500, self.max_params // 6))
        with self.transaction() as c:
            for i in range(0, len(latest), per):
                part = latest[i : i + per]
                c.execute(
                    "INSERT INTO tracks_latest (id, t_s, doc) VALUES "
                    + ",".join(["(?, ?, ?)"] * len(part))
                    + " ON CONFLICT(id) DO UPDATE SET t_s=excluded.t_s, doc=excluded.doc "
                    "WHERE excluded.t_s >= tracks_latest.t_s",
                    [v for t, d in part for v in (t.id, t.t_s, d)],
                )
            for i in range(0, len(docs), per):
                part = docs[i : i + per]
                c.execute(
                    "INSERT INTO track_history (track_id, t_s, lat_deg, lon_deg, alt_amsl_m, doc) "
                    "VALUES " + ",".join(["(?, ?, ?, ?, ?, ?)"] * len(part)),
                    [
                        v
                        for t, d in part
                        for v in (t.id, t.t_s, t.lat_deg, t.lon_deg, t.alt_amsl_m, d)
                    ],
                )

    def latest_tracks(self) -> list[Track]:
        return [
            self._load(Track, d) for (d,) in self._rows("SELECT doc FROM tracks_latest ORDER BY id")
        ]

    def track_history(
        self, track_id: TrackId | str, since_t_s: float = float("-inf")
    ) -> list[Track]:
        """Recorded states of one track at or after ``since_t_s``, in time order."""
        return [
            self._load(Track, d)
            for (d,) in self._rows(
                "SELECT doc FROM track_history WHERE track_id=? AND t_s>=? ORDER BY t_s, seq",
                (track_id, since_t_s),
            )
        ]

    # ---- Remote ID ----------------------------------------------------------------------
    def save_remote_ids(self, rows: Sequence[tuple[TrackId, RemoteIdentity]]) -> None:
        """The latest identity of each Remote ID source, on its track (one row per source;
        an older identity never replaces a newer one)."""
        with self.transaction() as c:
            for track_id, ident in rows:
                c.execute(
                    "INSERT INTO remote_ids "
                    "(source, track_id, updated_t_s, uas_id, operator_id, doc) "
                    "VALUES (?, ?, ?, ?, ?, ?) ON CONFLICT(source) DO UPDATE SET "
                    "track_id=excluded.track_id, updated_t_s=excluded.updated_t_s, "
                    "uas_id=excluded.uas_id, operator_id=excluded.operator_id, doc=excluded.doc "
                    "WHERE excluded.updated_t_s >= remote_ids.updated_t_s",
                    (
                        ident.source,
                        track_id,
                        ident.updated_t_s,
                        ident.uas_id,
                        ident.operator_id,
                        dumps(ident),
                    ),
                )

    def load_remote_ids(self) -> list[tuple[TrackId, RemoteIdentity]]:
        """(track id, identity) of every Remote ID source, by source."""
        return [
            (TrackId(tid), self._load(RemoteIdentity, d))
            for tid, d in self._rows("SELECT track_id, doc FROM remote_ids ORDER BY source")
        ]

    # ---- threats and recommendations ----------------------------------------------------
    def save_threat(self, threat: Threat) -> None:
        """Insert a threat or update it (its life cycle: OPEN, UPDATED, CLOSED). Only the life
        that wrote a row may update it: a row of an earlier life under the same id raises
        :class:`StoreError` and stays as it was."""
        epoch = self.epoch
        with self.transaction() as c:
            cur = c.execute(
                "INSERT INTO threats (id, kind, status, detected_at_s, doc, epoch) "
                "VALUES (?, ?, ?, ?, ?, ?) "
                "ON CONFLICT(id) DO UPDATE SET kind=excluded.kind, status=excluded.status, "
                "doc=excluded.doc WHERE threats.epoch = excluded.epoch",
                (
                    threat.id,
                    threat.kind.value,
                    threat.status.value,
                    threat.detected_at_s,
                    dumps(threat),
                    epoch,
                ),
            )
            if cur.rowcount == 0:
                raise StoreError(self._foreign("threat", threat.id, c, "threats", (threat.id,)))

    def load_threats(self, *, status: ThreatStatus | None = None) -> list[Threat]:
        if status is None:
            rows = self._rows("SELECT doc FROM threats ORDER BY detected_at_s, id")
        else:
            rows = self._rows(
                "SELECT doc FROM threats WHERE status=? ORDER BY detected_at_s, id", (status.value,)
            )
        return [self._load(Threat, d) for (d,) in rows]

    def open_threats_of_earlier_lives(self, epoch: int) -> list[Threat]:
        """Threats the lives before ``epoch`` left open (OPEN or UPDATED): a process that
        died (kill -9) closed nothing. A restart reviews them (gcs_utm.app.restart)."""
        rows = self._rows(
            "SELECT doc FROM threats WHERE status <> ? AND epoch < ? ORDER BY detected_at_s, id",
            (ThreatStatus.CLOSED.value, epoch),
        )
        return [self._load(Threat, d) for (d,) in rows]

    def settle_inherited(self, item: Threat | Recommendation) -> bool:
        """A later life ends what an earlier, dead life left open: a threat it closes (CLOSED)
        or a recommendation version still waiting for an answer (PROPOSED) whose prompt died
        with that life. The one exception to "a row of another life is never overwritten"
        (:meth:`save_threat`), and only for those rows: a closed threat or a version in any
        other state stays as it was. Returns whether the row changed."""
        closed, proposed = ThreatStatus.CLOSED.value, RecommendationState.PROPOSED.value
        with self.transaction() as c:
            if isinstance(item, Threat):
                cur = c.execute(
                    "UPDATE threats SET status=?, doc=? WHERE id=? AND epoch < ? AND status <> ?",
                    (item.status.value, dumps(item), item.id, self.epoch, closed),
                )
            else:
                cur = c.execute(
                    "UPDATE recommendations SET state=?, doc=? "
                    "WHERE id=? AND version=? AND epoch < ? AND state = ?",
                    (item.state.value, dumps(item), item.id, item.version, self.epoch, proposed),
                )
            return bool(cur.rowcount)

    def save_recommendation(self, rec: Recommendation) -> None:
        """Insert a version or update its state (the lifecycle of one id+version). Only the
        life that wrote a version may update it (see :meth:`save_threat`)."""
        epoch = self.epoch
        with self.transaction() as c:
            self._fenced(c, rec.operation_id)
            cur = c.execute(
                "INSERT INTO recommendations "
                "(id, version, state, threat_id, operation_id, created_t_s, doc, epoch) "
                "VALUES (?, ?, ?, ?, ?, ?, ?, ?) "
                "ON CONFLICT(id, version) DO UPDATE SET state=excluded.state, doc=excluded.doc "
                "WHERE recommendations.epoch = excluded.epoch",
                (
                    rec.id,
                    rec.version,
                    rec.state.value,
                    rec.threat_id,
                    rec.operation_id,
                    rec.created_t_s,
                    dumps(rec),
                    epoch,
                ),
            )
            if cur.rowcount == 0:
                raise StoreError(
                    self._foreign(
                        f"recommendation version {rec.version} of",
                        rec.id,
                        c,
                        "recommendations",
                        (rec.id, rec.version),
                    )
                )

    def _foreign(
        self, what: str, row_id: str, c: Connection, table: str, key: tuple[Any, ...]
    ) -> str:
        where = "id=?" if table == "threats" else "id=? AND version=?"
        row = c.execute(f"SELECT epoch FROM {table} WHERE {where}", key).fetchone()
        owner = "unknown" if row is None else str(row[0])
        return (
            f"{self.where}: {what} {row_id!r} was written by life {owner}, this is life "
            f"{self.epoch}: rows of another life are never overwritten (an id reused across "
            "a restart)"
        )

    def load_recommendations(
        self, *, state: RecommendationState | None = None, latest_only: bool = True
    ) -> list[Recommendation]:
        """Recommendations (the latest version of each id unless ``latest_only`` is False),
        optionally only those in ``state``."""
        sql = "SELECT doc FROM recommendations r"
        clauses: list[str] = []
        params: list[Any] = []
        if latest_only:
            clauses.append(
                "version = (SELECT MAX(version) FROM recommendations q WHERE q.id = r.id)"
            )
        if state is not None:
            clauses.append("state = ?")
            params.append(state.value)
        if clauses:
            sql += " WHERE " + " AND ".join(clauses)
        sql += " ORDER BY created_t_s, id, version"
        return [self._load(Recommendation, d) for (d,) in self._rows(sql, params)]

    def operation_of_recommendation(self, rec_id: str) -> str | None:
        """The operation a recommendation id is for (None: no version of it is stored)."""
        rows = self._rows(
            "SELECT operation_id FROM recommendations WHERE id = ? LIMIT 1", (rec_id,)
        )
        return str(rows[0][0]) if rows else None

    def versions_touched_by(self, epoch: int) -> list[tuple[str, int, str, int]]:
        """(id, version, state, epoch) of every version of each recommendation id that life
        ``epoch`` wrote a version of, in id and version order (a cluster member follows what
        the owner of another operation did with a recommendation it decided)."""
        return [
            (str(i), int(v), str(st), int(e))
            for i, v, st, e in self._rows(
                "SELECT id, version, state, epoch FROM recommendations WHERE id IN "
                "(SELECT id FROM recommendations WHERE epoch = ?) ORDER BY id, version",
                (epoch,),
            )
        ]

    def record_answer(self, answer: PilotAnswer) -> None:
        with self.transaction() as c:
            c.execute(
                "INSERT INTO answers (recommendation_id, version, decision, t_s, doc) "
                "VALUES (?, ?, ?, ?, ?)",
                (
                    answer.recommendation_id,
                    answer.version,
                    answer.decision.value,
                    answer.t_s,
                    dumps(answer),
                ),
            )

    def load_answers(self, recommendation_id: str | None = None) -> list[PilotAnswer]:
        if recommendation_id is None:
            rows = self._rows("SELECT doc FROM answers ORDER BY seq")
        else:
            rows = self._rows(
                "SELECT doc FROM answers WHERE recommendation_id=? ORDER BY seq",
                (recommendation_id,),
            )
        return [self._load(PilotAnswer, d) for (d,) in rows]

    # ---- audit --------------------------------------------------------------------------
    def audit(self, entry: AuditEntry) -> int:
        """Append one audit entry; returns its sequence number."""
        with self.transaction() as c:
            cur = c.execute(
                "INSERT INTO audit (t_s, actor, action, subject, detail) VALUES (?, ?, ?, ?, ?) "
                "RETURNING seq",
                (entry.t_s, entry.actor, entry.action, entry.subject, dumps(entry.detail)),
            )
            return int(cur.fetchone()[0])

    def latest_t_s(self) -> float | None:
        """The latest service time the store holds (its audit, plan versions and threats;
        None when empty): where a restarted service's clock resumes when it runs at a speed
        factor (gcs_utm.app.serve)."""
        row = self._conn.execute(
            "SELECT MAX(t) FROM (SELECT MAX(t_s) AS t FROM audit "
            "UNION ALL SELECT MAX(created_t_s) FROM flight_plans "
            "UNION ALL SELECT MAX(detected_at_s) FROM threats) AS times"
        ).fetchone()
        return None if row is None or row[0] is None else float(row[0])

    def load_audit(self, since_t_s: float = float("-inf")) -> list[AuditEntry]:
        out: list[AuditEntry] = []
        for t, actor, action, subject, detail in self._rows(
            "SELECT t_s, actor, action, subject, detail FROM audit WHERE t_s>=? ORDER BY seq",
            (since_t_s,),
        ):
            out.append(
                AuditEntry(
                    t_s=t,
                    actor=actor,
                    action=action,
                    subject=subject,
                    detail=self._load(dict[str, Any], detail),
                )
            )
        return out

    def count(self, table: str) -> int:
        if table not in TABLES:
            raise ValueError(f"unknown table {table!r}")
        return int(self._conn.execute(f"SELECT COUNT(*) FROM {table}").fetchone()[0])

    def _load(self, cls: Any, text: str) -> Any:
        try:
            return loads(cls, text)
        except (CodecError, ValueError, TypeError, KeyError) as exc:
            raise StoreError(f"{self.where}: a stored {cls!r} does not decode: {exc}") from exc


TABLES = frozenset(
    {
        "operations",
        "flight_plans",
        "geofences",
        "tracks_latest",
        "track_history",
        "threats",
        "recommendations",
        "answers",
        "audit",
        "lives",
        "regions",
        "region_leases",
        "remote_ids",
    }
)

__all__ = [
    "TABLES",
    "Connection",
    "Cursor",
    "FencedError",
    "StoreBase",
    "StoreError",
    "track_doc",
]
