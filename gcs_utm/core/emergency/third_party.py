"""A UAS outside the threat that the immediate command would meet is commanded too.

:func:`~.immediate.choose_commands` flies the commands of the threat's UAS against all other
traffic, and when no combination keeps the minima it takes the one that separates best, the
smallest ratio over every pair. When that smallest ratio is against a UAS outside the
threat, the command avoids the threat's loss by running into another one: a multirotor
overtaking another was told to climb in place (every combination of the pair lost the minima
to a fixed wing coming up behind it, 17 m lower), stopped in the fixed wing's path, and the
loss with it was first predicted 3.8 s ahead (``enc_3_0217_late_overtaking``, UAS2-UAS5
47.0 m / 37.6 m against 50 / 40 m, counted as created by an accepted plan). So the choice is
made again with that UAS among the candidates (up to ``immediate.MAX_UAS``): the fixed wing
may descend while the multirotor climbs. The second choice is kept when it keeps the
minima, or separates at least :data:`MIN_GAIN` (in separation ratio) better than the first:
a third UAS is not commanded for nothing. Pure.
"""

from __future__ import annotations

from gcs_utm.core.emergency.fly_on import Choice
from gcs_utm.model import OperationId

MIN_GAIN = 0.05
"""How much more separation ratio a choice commanding a UAS outside the threat must keep."""


def limiting_outsider(
    first: tuple[Choice, OperationId | None], n_candidates: int, max_uas: int
) -> OperationId | None:
    """The UAS outside the threat to add to the candidates, from the first choice and the
    UAS that limits it (None: there is none, the choice keeps the minima or proposes no
    command, or the candidates are full)."""
    choice, outsider = first
    if outsider is None or choice.clear or not choice.commands or n_candidates >= max_uas:
        return None
    return outsider


def better(first: Choice, second: Choice) -> Choice:
    """``second`` (chosen with the UAS outside the threat) when it keeps the minima and
    ``first`` does not, or it separates :data:`MIN_GAIN` better; else ``first``."""
    if second.clear and not first.clear:
        return second
    if second.commands and second.ratio >= first.ratio + MIN_GAIN:
        return second
    return first
