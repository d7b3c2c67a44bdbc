"""Schema of the store as numbered migrations; ``PRAGMA user_version`` is the number applied.

Never edit a released migration: append a new one. A database newer than this code is
refused rather than written with a schema we do not know.
"""

from __future__ import annotations

MIGRATIONS: tuple[str, ...] = (
    # 1: the paper's Data Base (Tables 2 and 3) plus tracking history, decisions and audit.
    """
    CREATE TABLE operations (
        id TEXT PRIMARY KEY,
        state TEXT NOT NULL,
        updated_t_s REAL NOT NULL,
        doc TEXT NOT NULL
    );
    CREATE TABLE flight_plans (
        operation_id TEXT NOT NULL,
        version INTEGER NOT NULL,
        created_t_s REAL NOT NULL,
        reason TEXT NOT NULL,
        start_t_s REAL NOT NULL,
        end_t_s REAL NOT NULL,
        waypoints TEXT NOT NULL,
        PRIMARY KEY (operation_id, version)
    );
    CREATE TABLE geofences (
        id TEXT PRIMARY KEY,
        active INTEGER NOT NULL,
        start_t_s REAL,
        end_t_s REAL,
        doc TEXT NOT NULL
    );
    CREATE TABLE tracks_latest (
        id TEXT PRIMARY KEY,
        t_s REAL NOT NULL,
        doc TEXT NOT NULL
    );
    CREATE TABLE track_history (
        seq INTEGER PRIMARY KEY AUTOINCREMENT,
        track_id TEXT NOT NULL,
        t_s REAL NOT NULL,
        lat_deg REAL NOT NULL,
        lon_deg REAL NOT NULL,
        alt_amsl_m REAL NOT NULL,
        doc TEXT NOT NULL
    );
    CREATE INDEX track_history_by_track ON track_history (track_id, t_s);
    CREATE TABLE threats (
        id TEXT PRIMARY KEY,
        kind TEXT NOT NULL,
        status TEXT NOT NULL,
        detected_at_s REAL NOT NULL,
        doc TEXT NOT NULL
    );
    CREATE TABLE recommendations (
        id TEXT NOT NULL,
        version INTEGER NOT NULL,
        state TEXT NOT NULL,
        threat_id TEXT NOT NULL,
        operation_id TEXT NOT NULL,
        created_t_s REAL NOT NULL,
        doc TEXT NOT NULL,
        PRIMARY KEY (id, version)
    );
    CREATE TABLE answers (
        seq INTEGER PRIMARY KEY AUTOINCREMENT,
        recommendation_id TEXT NOT NULL,
        version INTEGER NOT NULL,
        decision TEXT NOT NULL,
        t_s REAL NOT NULL,
        doc TEXT NOT NULL
    );
    CREATE TABLE audit (
        seq INTEGER PRIMARY KEY AUTOINCREMENT,
        t_s REAL NOT NULL,
        actor TEXT NOT NULL,
        action TEXT NOT NULL,
        subject TEXT NOT NULL,
        detail TEXT NOT NULL
    );
    CREATE INDEX audit_by_time ON audit (t_s);
    """,
    # 2: lives. Every process that writes decisions begins a life (one row here, a new epoch);
    # threat and recommendation rows carry the epoch that wrote them, and a life never
    # updates a row of another (see Store.save_threat). Rows written before this migration get
    # epoch 0, a life no process has: they are never overwritten either.
    """
    CREATE TABLE lives (
        epoch INTEGER PRIMARY KEY AUTOINCREMENT,
        started_unix_s REAL NOT NULL,
        pid INTEGER NOT NULL
    );
    ALTER TABLE threats ADD COLUMN epoch INTEGER NOT NULL DEFAULT 0;
    ALTER TABLE recommendations ADD COLUMN epoch INTEGER NOT NULL DEFAULT 0;
    """,
    # 3: regions of a cluster (docs/scale-out.md): the region map every instance shares (one
    # row per region, its definition as JSON) and the lease by which one instance owns each
    # region (holder = instance name and life; generation counts changes of holder, a fencing
    # number; times are the database's clock, so the instances' clocks need not agree).
    """
    CREATE TABLE regions (
        id TEXT PRIMARY KEY,
        doc TEXT NOT NULL
    );
    CREATE TABLE region_leases (
        region_id TEXT PRIMARY KEY,
        holder TEXT NOT NULL,
        epoch INTEGER NOT NULL,
        generation INTEGER NOT NULL,
        acquired_unix_s REAL NOT NULL,
        expires_unix_s REAL NOT NULL
    );
    """,
    # 4: the number of the last batch each life's writer committed, written in the batch's own
    # transaction, so a batch retried after a lost connection (or replayed from the local
    # journal, gcs_utm/store/journal.py) is known to have committed and is not applied twice.
    """
    ALTER TABLE lives ADD COLUMN committed_batch INTEGER NOT NULL DEFAULT 0;
    """,
    # 5: Remote ID (docs/remote-id.md): the latest identity and location each Remote ID
    # source (sysid:<n> or rid:<hex>) gave, on the track it belongs on; doc is the
    # RemoteIdentity as JSON.
    """
    CREATE TABLE remote_ids (
        source TEXT PRIMARY KEY,
        track_id TEXT NOT NULL,
        updated_t_s REAL NOT NULL,
        uas_id TEXT NOT NULL,
        operator_id TEXT NOT NULL,
        doc TEXT NOT NULL
    );
    """,
)

# The same schema in PostgreSQL, migration for migration (number n here is number n above):
# the same tables, columns and indexes; REAL is DOUBLE PRECISION, AUTOINCREMENT an identity
# column (a sequence never hands a number out twice, as AUTOINCREMENT does not). The applied
# number is kept in the one-row table gcs_utm_schema (PostgreSQL has no user_version).
PG_MIGRATIONS: tuple[str, ...] = (
    """
    CREATE TABLE operations (
        id TEXT PRIMARY KEY,
        state TEXT NOT NULL,
        updated_t_s DOUBLE PRECISION NOT NULL,
        doc TEXT NOT NULL
    );
    CREATE TABLE flight_plans (
        operation_id TEXT NOT NULL,
        version INTEGER NOT NULL,
        created_t_s DOUBLE PRECISION NOT NULL,
        reason TEXT NOT NULL,
        start_t_s DOUBLE PRECISION NOT NULL,
        end_t_s DOUBLE PRECISION NOT NULL,
        waypoints TEXT NOT NULL,
        PRIMARY KEY (operation_id, version)
    );
    CREATE TABLE geofences (
        id TEXT PRIMARY KEY,
        active INTEGER NOT NULL,
        start_t_s DOUBLE PRECISION,
        end_t_s DOUBLE PRECISION,
        doc TEXT NOT NULL
    );
    CREATE TABLE tracks_latest (
        id TEXT PRIMARY KEY,
        t_s DOUBLE PRECISION NOT NULL,
        doc TEXT NOT NULL
    );
    CREATE TABLE track_history (
        seq BIGINT GENERATED BY DEFAULT AS IDENTITY PRIMARY KEY,
        track_id TEXT NOT NULL,
        t_s DOUBLE PRECISION NOT NULL,
        lat_deg DOUBLE PRECISION NOT NULL,
        lon_deg DOUBLE PRECISION NOT NULL,
        alt_amsl_m DOUBLE PRECISION NOT NULL,
        doc TEXT NOT NULL
    );
    CREATE INDEX track_history_by_track ON track_history (track_id, t_s);
    CREATE TABLE threats (
        id TEXT PRIMARY KEY,
        kind TEXT NOT NULL,
        status TEXT NOT NULL,
        detected_at_s DOUBLE PRECISION NOT NULL,
        doc TEXT NOT NULL
    );
    CREATE TABLE recommendations (
        id TEXT NOT NULL,
        version INTEGER NOT NULL,
        state TEXT NOT NULL,
        threat_id TEXT NOT NULL,
        operation_id TEXT NOT NULL,
        created_t_s DOUBLE PRECISION NOT NULL,
        doc TEXT NOT NULL,
        PRIMARY KEY (id, version)
    );
    CREATE TABLE answers (
        seq BIGINT GENERATED BY DEFAULT AS IDENTITY PRIMARY KEY,
        recommendation_id TEXT NOT NULL,
        version INTEGER NOT NULL,
        decision TEXT NOT NULL,
        t_s DOUBLE PRECISION NOT NULL,
        doc TEXT NOT NULL
    );
    CREATE TABLE audit (
        seq BIGINT GENERATED BY DEFAULT AS IDENTITY PRIMARY KEY,
        t_s DOUBLE PRECISION NOT NULL,
        actor TEXT NOT NULL,
        action TEXT NOT NULL,
        subject TEXT NOT NULL,
        detail TEXT NOT NULL
    );
    CREATE INDEX audit_by_time ON audit (t_s);
    """,
    """
    CREATE TABLE lives (
        epoch BIGINT GENERATED BY DEFAULT AS IDENTITY PRIMARY KEY,
        started_unix_s DOUBLE PRECISION NOT NULL,
        pid INTEGER NOT NULL
    );
    ALTER TABLE threats ADD COLUMN epoch INTEGER NOT NULL DEFAULT 0;
    ALTER TABLE recommendations ADD COLUMN epoch INTEGER NOT NULL DEFAULT 0;
    """,
    """
    CREATE TABLE regions (
        id TEXT PRIMARY KEY,
        doc TEXT NOT NULL
    );
    CREATE TABLE region_leases (
        region_id TEXT PRIMARY KEY,
        holder TEXT NOT NULL,
        epoch INTEGER NOT NULL,
        generation INTEGER NOT NULL,
        acquired_unix_s DOUBLE PRECISION NOT NULL,
        expires_unix_s DOUBLE PRECISION NOT NULL
    );
    """,
    """
    ALTER TABLE lives ADD COLUMN committed_batch BIGINT NOT NULL DEFAULT 0;
    """,
    """
    CREATE TABLE remote_ids (
        source TEXT PRIMARY KEY,
        track_id TEXT NOT NULL,
        updated_t_s DOUBLE PRECISION NOT NULL,
        uas_id TEXT NOT NULL,
        operator_id TEXT NOT NULL,
        doc TEXT NOT NULL
    );
    """,
)
