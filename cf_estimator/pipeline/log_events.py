"""What the node's log says about resets, rejections and events: one WARN each, rate-limited.

/diagnostics counts every reset, rejection and event (an attitude error revealed while aided),
but a launch screen only shows the log. The node feeds the pipeline's cumulative counters to
:class:`RateLimitedWarnings` after a rejected message, a reset or an event; it returns the
lines to log: one per reset (``filter reset (time_jump_back): ...``) or event, and one for the
first rejection of each kind, then at most one per :attr:`period_s` for each key, summing up
what happened in between. No ROS, no clock of its
own: the caller passes the time (the node: the steady clock), so the tests need no sleeps.
"""

from __future__ import annotations

from collections.abc import Mapping

#: What each reset reason means, for the log line.
RESET_TEXT = {
    "time_jump_back": "the IMU stamps went back by more than time_jump_back_threshold_s",
    "long_gap": "an IMU stamp gap longer than reset_after_gap_s",
    "clock_jump_back": "the node clock jumped back (use_sim_time rewind)",
}
#: What each event means, for the log line.
EVENT_TEXT = {
    "attitude_error": "velocity-aided, the tilt was off the gravity the velocity window "
                      "measured by more than an attitude error's worth (a gyro fault or "
                      "over-range): the filter took hold again, learning no gyro bias from it",
}


class RateLimitedWarnings:
    """Turn cumulative reset / rejection counters into log lines (see the module docstring).

    ``period_s`` [s]: the shortest interval between two lines of one key (a reset reason, or a
    rejection reason); what is held back meanwhile is counted in the next line of that key.
    """

    def __init__(self, period_s: float = 5.0) -> None:
        self.period_s = period_s
        self._seen: dict[str, int] = {}
        self._reported: dict[str, int] = {}
        self._last_s: dict[str, float] = {}

    def _due(self, key: str, now_s: float) -> bool:
        last = self._last_s.get(key)
        return last is None or now_s - last >= self.period_s

    def update(self, resets: Mapping[str, int], rejected: Mapping[str, int],
               now_s: float, events: Mapping[str, int] | None = None) -> list[str]:
        """The lines to log now for these cumulative counters (``reason → count``)."""
        out: list[str] = []
        for kind, counts in (("reset", resets), ("rejected", rejected),
                             ("event", events or {})):
            for reason, n in counts.items():
                key = f"{kind}.{reason}"
                if n <= self._seen.get(key, 0):
                    continue
                self._seen[key] = n
                if not self._due(key, now_s):
                    continue
                new = n - self._reported.get(key, 0)
                self._reported[key] = n
                self._last_s[key] = now_s
                out.append(self._text(kind, reason, n, new))
        return out

    def flush(self, now_s: float) -> list[str]:
        """Lines for what was held back and is due now (the node calls it with diagnostics)."""
        out = []
        for key, n in self._seen.items():
            if n > self._reported.get(key, 0) and self._due(key, now_s):
                kind, reason = key.split(".", 1)
                out.append(self._text(kind, reason, n, n - self._reported.get(key, 0)))
                self._reported[key] = n
                self._last_s[key] = now_s
        return out

    @staticmethod
    def _text(kind: str, reason: str, total: int, new: int) -> str:
        if kind == "event":
            more = f" ({new} since the last report)" if new > 1 else ""
            return (f"{reason}: {EVENT_TEXT.get(reason, reason)}{more}; {total} so far, "
                    "counted in /diagnostics")
        if kind == "reset":
            why = RESET_TEXT.get(reason, reason)
            more = f" ({new} since the last report)" if new > 1 else ""
            return (f"filter reset ({reason}): {why}; the attitude starts again from the next "
                    f"message{more}; {total} reset(s) {reason} so far")
        if total == new:
            return (f"IMU message rejected: {reason} (first of its kind; {total} so far, "
                    "counted in /diagnostics)")
        return f"IMU messages rejected: {reason}, {new} more ({total} so far)"
