"""Summaries (max, 99th percentile, median) and the plain text tables the check prints."""
from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np


@dataclass
class Summary:
    """max, 99th percentile and median of a set of values (nan when empty)."""

    count: int
    max: float
    p99: float
    median: float

    @classmethod
    def of(cls, values) -> "Summary":
        values = np.asarray(values, np.float64).ravel()
        if values.size == 0:
            return cls(0, math.nan, math.nan, math.nan)
        return cls(values.size, float(values.max()), float(np.percentile(values, 99)), float(np.median(values)))

    def scaled(self, factor: float) -> "Summary":
        return Summary(self.count, self.max * factor, self.p99 * factor, self.median * factor)


def _number(value: float) -> str:
    if math.isnan(value):
        return "-"
    if value == 0:
        return "0"
    return f"{value:.3g}" if 1e-3 <= abs(value) < 1e4 else f"{value:.2e}"


def table(title: str, rows, header=("", "max", "p99", "median")) -> str:
    """A plain text table: rows of (label, Summary) or (label, text)."""
    lines = [title]
    cells = []
    for label, value in rows:
        if isinstance(value, Summary):
            cells.append((label, _number(value.max), _number(value.p99), _number(value.median)))
        else:
            cells.append((label, str(value)))
    widths = [max(len(header[0]), *(len(c[0]) for c in cells))] + [11, 11, 11]
    header_done = False
    for c in cells:
        if len(c) == 4 and not header_done:
            lines.append("  " + header[0].ljust(widths[0]) + "".join(h.rjust(w) for h, w in zip(header[1:], widths[1:])))
            header_done = True
        if len(c) == 4:
            lines.append("  " + c[0].ljust(widths[0]) + "".join(v.rjust(w) for v, w in zip(c[1:], widths[1:])))
        else:
            lines.append("  " + c[0].ljust(widths[0]) + "  " + c[1])
    return "\n".join(lines)


def disagreement_kinds(disagree, reasons) -> dict:
    """Each disagreeing pixel or ray counted once, under the first of ``reasons`` ((name, mask)
    pairs) that explains it; the rest are "unexplained"."""
    left = disagree.copy()
    out = {}
    for name, reason in reasons:
        out[name] = int((left & reason).sum())
        left &= ~reason
    out["unexplained"] = int(left.sum())
    return out
