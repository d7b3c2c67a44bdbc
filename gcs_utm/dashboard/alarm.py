"""The expiry alarm: a recommendation nobody answered in time is impossible to miss.

:class:`ExpiryAlarms` keeps, per recommendation id, the version that expired and what
followed it (EM's re-proposal of the safe command, ``[emergency] expiry_action``), and words
the alarm line the dashboard shows as a red banner (with the terminal bell) and the line
prompt prints as ``!!! EXPIRED ...``. Pure bookkeeping (wall time passed in), no I/O.
"""

from __future__ import annotations

from dataclasses import dataclass

from gcs_utm.core.emergency.wording import proposal_text
from gcs_utm.model import Recommendation, RecommendationId


@dataclass(slots=True, kw_only=True)
class _Expired:
    version: int
    operation_id: str
    proposed: str
    at_wall_s: float
    next: str = ""


class ExpiryAlarms:
    """Expired recommendations and their re-proposals, newest last. An alarm stays up for
    ``hold_s`` wall seconds after its last news, or until :meth:`acknowledge`."""

    def __init__(self, hold_s: float = 30.0) -> None:
        self.hold_s = hold_s
        self._alarms: dict[RecommendationId, _Expired] = {}

    def expired(self, rec: Recommendation, now_wall_s: float) -> str:
        """``rec`` expired without an answer: its alarm line."""
        self._alarms.pop(rec.id, None)  # newest last
        self._alarms[rec.id] = _Expired(
            version=rec.version,
            operation_id=rec.operation_id,
            proposed=proposal_text(rec),
            at_wall_s=now_wall_s,
        )
        return self.text(rec.id)

    def proposed(self, rec: Recommendation, now_wall_s: float) -> str:
        """A new proposal: when it follows an expiry of the same id, the alarm says so (see
        :meth:`text`) and a line announcing it is returned ("" otherwise)."""
        alarm = self._alarms.get(rec.id)
        if alarm is None or rec.version <= alarm.version:
            return ""
        what = f"{proposal_text(rec)}; answer it now"
        alarm.next = f"v{rec.version} proposed instead: {what}"
        alarm.at_wall_s = now_wall_s
        return f"!!! {rec.id} v{rec.version} proposed instead of expired v{alarm.version}: {what}"

    def text(self, rec_id: RecommendationId) -> str:
        alarm = self._alarms.get(rec_id)
        if alarm is None:
            return ""
        nxt = alarm.next or "The UAS flies on unchanged: nothing was sent to it"
        return (
            f"!!! EXPIRED {rec_id} v{alarm.version} ({alarm.operation_id}): nobody answered "
            f"in time ({alarm.proposed}). {nxt}"
        )

    def _live(self, now_wall_s: float) -> list[RecommendationId]:
        return [k for k, a in self._alarms.items() if now_wall_s - a.at_wall_s < self.hold_s]

    def current(self, now_wall_s: float) -> str:
        """The newest alarm still up ("" when none)."""
        live = self._live(now_wall_s)
        return self.text(live[-1]) if live else ""

    def short(self, now_wall_s: float) -> str:
        """The newest alarm still up in a few words, for a prompt's title ("" when none)."""
        live = self._live(now_wall_s)
        if not live:
            return ""
        return f"!!! EXPIRED {live[-1]} v{self._alarms[live[-1]].version}: nobody answered"

    def acknowledge(self) -> None:
        """The pilot answered: the alarms have been seen."""
        self._alarms.clear()
