"""Does an immediate command take its UAS into a geofence?

A hold, or a climb or descent in place, keeps a multirotor where it stops and a fixed wing
circling where it was commanded (:mod:`.immediate`). Chosen by separation alone, the circle
of a fixed wing told to climb beside the encounter crossed a no-fly zone 33 m in radius
(4 s inside), and a fixed wing circling just outside one was predicted into it and re-routed
inside. The positions a command gives its UAS, with the horizontal room it takes (a fixed
wing's circle), are checked against every active geofence that applies to the UAS, grown by
its operational volume (the clearance TD keeps its plans at), from the command on;
:func:`~.immediate.choose_commands` then prefers combinations that enter none.

A command may also take its UAS into the fence itself: the fence grown only by the UAS's
flight geometry (how far its track may be from where it is predicted), not the whole
volume. Such a command is an intrusion, not a clearance kept short, and ranks after every
command that does not (:func:`fence_itself_entered`). Pure.
"""

from __future__ import annotations

from typing import TYPE_CHECKING

import numpy as np

from gcs_utm.model import AirspaceSnapshot, FloatArray, OperationId

if TYPE_CHECKING:
    from gcs_utm.core.deconfliction import TacticalDeconfliction


def fence_entered(  # noqa: PLR0917 - the command's context, then its positions
    td: TacticalDeconfliction,
    snapshot: AirspaceSnapshot,
    op_id: OperationId,
    xyz: FloatArray,
    slack_m: FloatArray,
    grid: FloatArray,
    from_t_s: float,
    *,
    grow_m: float | None = None,
) -> str:
    """The id of the first geofence, grown by the UAS's operational volume (as TD keeps its
    plans from fences; ``grow_m`` when given), that the positions ``xyz`` (on ``grid``, from
    ``from_t_s`` on), each anywhere within ``slack_m`` horizontally, come inside of, among
    those active then that apply to ``op_id`` ("" when none)."""
    after = grid >= from_t_s
    op = snapshot.operations.get(op_id)
    if grow_m is None:
        grow_m = 0.0 if op is None else op.operational_volume_m
    for g in snapshot.geofences:
        if not g.applies_to(op_id):
            continue
        f = td.local_fences([g])[0]
        near = f.horizontal_distance(xyz[:, 0], xyz[:, 1]) - slack_m - grow_m < 0.0
        z = xyz[:, 2]
        level = (z >= f.min_alt_amsl_m - grow_m) & (z <= f.max_alt_amsl_m + grow_m)
        if np.any(near & level & f.active_mask(grid) & after):
            return str(g.id)
    return ""


def fence_itself_entered(  # noqa: PLR0917 - as fence_entered
    td: TacticalDeconfliction,
    snapshot: AirspaceSnapshot,
    op_id: OperationId,
    xyz: FloatArray,
    slack_m: FloatArray,
    grid: FloatArray,
    from_t_s: float,
) -> str:
    """:func:`fence_entered` with the fences grown only by the UAS's flight geometry: the
    positions come near enough to a fence that the vehicle, within its tracking error of
    them, may be inside it."""
    op = snapshot.operations.get(op_id)
    grow_m = 0.0 if op is None else op.flight_geometry_m
    return fence_entered(td, snapshot, op_id, xyz, slack_m, grid, from_t_s, grow_m=grow_m)
