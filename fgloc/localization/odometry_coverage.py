"""Which spans of log time the odometry's stamps cover (:class:`OdometryCoverage`): the jump gate
(:mod:`fgloc.localization.gate`) counts the odometry's motion between two fixes only where they cover it.
Core maths only: no I/O."""

from __future__ import annotations


class OdometryCoverage:
    """Which spans of log time the odometry's stamps cover (not their arrival): consecutive stamps at
    most ``max_gap_s`` apart.  The motion between two fixes is known only where the odometry covers
    the whole span between them: odometry that arrives late (its newest stamp behind the scan's),
    stopped (a dead wheel driver) or was absent for a stretch leaves the motion there unknown."""

    MAX_GAPS = 256  # the long gaps remembered (the oldest forgotten first)

    def __init__(self, max_gap_s: float) -> None:
        self.max_gap_s = float(max_gap_s)
        self.first: float | None = None
        self.last: float | None = None
        self._gaps: list[tuple[float, float]] = []  # (last stamp before, first stamp after) a gap > max_gap_s

    def add(self, t: float) -> None:
        """An odometry message stamped ``t`` (stamps of one stream only grow)."""
        t = float(t)
        last = self.last
        if self.first is None:
            self.first = t
        elif last is not None and t - last > self.max_gap_s:
            self._gaps.append((last, t))
            if len(self._gaps) > self.MAX_GAPS:
                del self._gaps[0]
        if last is None or t > last:  # (the later of the two)
            self.last = t

    def covers(self, t0: float, t1: float) -> bool:
        """Whether the stamps cover ``[t0, t1]``: one within ``max_gap_s`` of each end and no longer
        stretch without one between."""
        g = self.max_gap_s
        if self.first is None or self.last is None or self.first > t0 + g or self.last < t1 - g:
            return False
        return not self._gaps or not any(min(b, t1) - max(a, t0) > g for a, b in self._gaps)

    def uncovered_s(self, t0: float, t1: float) -> float:
        """How long of ``[t0, t1]`` the stamps leave uncovered (the gaps, before the first and after the last)."""
        if self.first is None or self.last is None:
            return max(0.0, t1 - t0)
        out = max(0.0, min(t1, self.first) - t0) + max(0.0, t1 - max(t0, self.last))
        out += sum(max(0.0, min(b, t1) - max(a, t0)) for a, b in self._gaps)
        return out


__all__ = ["OdometryCoverage"]
