"""Settings of a cluster member (section ``[cluster]``, used by ``serve --cluster``)."""

from __future__ import annotations

import re
from dataclasses import dataclass

from gcs_utm.config import setting

_NAME = re.compile(r"^[A-Za-z0-9_.-]{1,64}$")


@dataclass(frozen=True, slots=True, kw_only=True)
class ClusterConfig:
    """One instance of several sharing the airspace through the store and the MQTT broker."""

    instance: str = setting(
        "", "this instance's name in leases and logs (letters, digits, _ . -); empty: host-pid"
    )
    region: str = setting(
        "", "the region this instance owns when it is free, e.g. 'c0r0' (column 0, row 0)"
    )
    standby: bool = setting(
        True, "take over any region whose owner's lease expired (the owner died)"
    )
    west_m: float = setting(
        -5000.0, "west edge of the region grid, east of the airspace origin", unit="m"
    )
    south_m: float = setting(
        -5000.0, "south edge of the region grid, north of the airspace origin", unit="m"
    )
    cell_m: float = setting(5000.0, "side of one square region", min=1.0, unit="m")
    columns: int = setting(2, "regions west to east", min=1, max=1000)
    rows: int = setting(2, "regions south to north", min=1, max=1000)
    halo_m: float = setting(
        1000.0,
        "margin around a region within which its owner also watches the neighbours' traffic "
        "(exchanged over MQTT): at least the separation minimum plus what a UAS flies in the "
        "monitoring look-ahead",
        min=0.0,
        unit="m",
    )
    lease_s: float = setting(
        3.0,
        "a region lease expires this long after its last renewal; a standby takes the region "
        "over after it (the failover time is at most lease_s + renew_s)",
        min=0.5,
        unit="s",
    )
    renew_s: float = setting(
        1.0,
        "how often the owner renews its leases and a standby looks for expired ones",
        min=0.05,
        unit="s",
    )

    def __post_init__(self) -> None:
        if self.instance and not _NAME.match(self.instance):
            raise ValueError(
                f"cluster.instance: expected letters, digits, _ . - (1..64), got {self.instance!r}"
            )
        if self.halo_m >= self.cell_m:
            raise ValueError(
                f"cluster.halo_m: expected less than cell_m ({self.cell_m} m), got "
                f"{self.halo_m} m: a halo reaches the next region only"
            )
        if self.renew_s * 2 > self.lease_s:
            raise ValueError(
                f"cluster.renew_s: expected at most half of lease_s ({self.lease_s} s), got "
                f"{self.renew_s} s: one late renewal would lose the lease"
            )
