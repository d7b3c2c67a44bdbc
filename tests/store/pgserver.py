"""The private PostgreSQL server of the tests (:mod:`gcs_utm.cluster.localpg`)."""

from gcs_utm.cluster.localpg import PgServer, start

__all__ = ["PgServer", "start"]
