"""Who is wrong where pyclray and Mitsuba disagree: the float64 oracle decides.

A disagreement (a pixel or ray whose two results differ beyond the tolerance between the engines) is
looked at once more, each engine against the oracle with its own bound of the error model: pyclray's
(``error_model.pyclray_tolerances``, K = 4 against the oracle) and Mitsuba's
(``error_model.mitsuba_tolerances``). It is

- pyclray's fault where pyclray is outside its bound (whatever Mitsuba does: the check fails);
- Mitsuba's fault where pyclray is within its bound and Mitsuba outside its own;
- undecided where the geometry leaves the answer open (silhouettes, edges, near ties: the error
  model's rules, which say either answer is right) or where both are within their bounds.

Only pyclray's faults fail the check; Mitsuba's are counted and said.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..error_model import angle_between


@dataclass
class Verdicts:
    """Counts of one AOV's disagreements by who the oracle says is wrong."""

    disagree: int = 0
    pyclray: int = 0
    mitsuba: int = 0
    undecided: int = 0

    def __add__(self, other: "Verdicts") -> "Verdicts":
        return Verdicts(self.disagree + other.disagree, self.pyclray + other.pyclray, self.mitsuba + other.mitsuba,
                        self.undecided + other.undecided)


def decide(disagree, pyclray_wrong, mitsuba_wrong, undecided=None) -> Verdicts:
    """The verdicts over the masks: ``undecided`` marks where the geometry leaves it open."""
    disagree = np.asarray(disagree, bool)
    open_ = np.zeros_like(disagree) if undecided is None else np.asarray(undecided, bool)
    decided = disagree & ~open_
    ours = decided & pyclray_wrong
    theirs = decided & ~pyclray_wrong & mitsuba_wrong
    return Verdicts(int(disagree.sum()), int(ours.sum()), int(theirs.sum()), int((disagree & ~ours & ~theirs).sum()))


def wrong_hits(result: dict, truth: dict, depth_tolerance, normal_tolerance) -> dict:
    """Per AOV, where an engine's result (depth, normal, id) is wrong by the oracle's ``truth``:
    another shape (or a hit for a miss), a depth or a normal outside the engine's own bounds."""
    ids = np.asarray(result["id"])
    other = ids != truth["id"]
    hit = (ids >= 0) & ~other
    with np.errstate(invalid="ignore"):
        depth = np.abs(np.asarray(result["depth"], np.float64) - truth["depth"]) > depth_tolerance
        normal = angle_between(result["normal"], truth["normal"]) > normal_tolerance
    return {"id": other, "depth": other | (hit & depth), "normal": other | (hit & normal)}


def verdict_rows(verdicts: dict) -> list:
    """The rows of the arbitration table: (label, text) per AOV."""
    header = ("", "disagree  pyclray's fault  Mitsuba's fault  undecided")
    rows = [header]
    for name, v in verdicts.items():
        rows.append((name, f"{v.disagree:8d}  {v.pyclray:15d}  {v.mitsuba:15d}  {v.undecided:9d}"))
    return rows


def mitsuba_faults(verdicts: dict) -> str:
    """'Mitsuba is wrong on N pixels (depth a, ...)' or '' when it is nowhere."""
    total = sum(v.mitsuba for v in verdicts.values())
    if not total:
        return ""
    parts = ", ".join(f"{name} {v.mitsuba}" for name, v in verdicts.items() if v.mitsuba)
    return f"Mitsuba is wrong on {total} pixels or rays ({parts}), where the float64 oracle agrees with pyclray"
