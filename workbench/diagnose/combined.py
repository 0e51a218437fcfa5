"""Several candidates fitted as one: :class:`Combined` and :func:`combine` (the sets of
:mod:`.sets`)."""

from __future__ import annotations

from dataclasses import dataclass, field, replace
from typing import Any, Mapping, Sequence

from .candidates import Candidate

__all__ = ["Combined", "combine"]


@dataclass(frozen=True)
class Combined(Candidate):
    """Several candidates fitted together (their values all free at once)."""

    members: tuple[Candidate, ...] = ()
    nominal_point: Mapping[str, float] = field(default_factory=dict)
    subset_points: tuple[Mapping[str, float], ...] = ()
    scan_points: tuple[Mapping[str, float], ...] = ()

    def split(self, values: Mapping[str, float]) -> list[dict[str, float]]:
        """The fitted values of each member (candidate keys)."""
        return [{f.key: values[f.key] for f in m.free if f.key in values} for m in self.members]

    def grid_points(self) -> list[dict[str, float]]:
        """Every member at its start value; the corrected nominal values back at the
        plant file's (:func:`combine`); each subset's fit with the left-out member at
        its neutral values (:func:`combine`); then the scanned members' grids, one
        member at a time."""
        return [{}] + ([dict(self.nominal_point)] if self.nominal_point else []) \
            + [dict(p) for p in self.subset_points] + [dict(p) for p in self.scan_points] \
            + (super().grid_points() if self.grid else [])

    def plant_values(self, values: Mapping[str, float]) -> dict[str, Any]:
        out: dict[str, Any] = {}
        for m, v in zip(self.members, self.split(values)):
            out.update(m.plant_values(v))
        return out


def combine(members: Sequence[Candidate], starts: Mapping[str, float] | None = None,
            scan: Candidate | Sequence[Candidate] | None = None,
            subsets: Sequence[Mapping[str, float]] = ()) -> Combined | None:
    """The joint candidate of ``members`` (None when two of them set the same plant key
    or are the same effect).

    ``starts`` (candidate keys -> values, e.g. the single fits) become the start values;
    the joint signature scan is ``scan``'s grid (each of several in turn) with the
    others at their start values (one member is scanned while the others keep what
    they explained alone), plus the
    point where every member is at its start value, plus ``subsets``: the fitted values
    of the sets with one member left out, that member at its neutral values
    (:meth:`Candidate.neutral_values`). A set contains each of its subsets as that
    special case, so its fit starting from the best of them is never worse than the
    subset's (measured without these points: valve_deadband + valve_offset refitted
    from the singles' values cost 5849 noise units where the deadband alone, fitted
    37 % too wide to mimic the offset, cost 4955; the offset's own share came out
    negative and the offset was not named)."""
    keys: set[str] = set()
    effects: set[str] = set()
    for m in members:
        mk = {f.key for f in m.free} | set(m.fixed)
        if mk & keys or (m.effect != "parameter_error" and m.effect in effects):
            return None
        keys |= mk
        effects.add(m.effect)
    fixed: dict[str, Any] = {}
    for m in members:
        fixed.update(m.fixed)
    starts = starts or {}
    # a nominal value refitted alone may have drifted far to mimic another member's
    # effect (measured: with a deadband, mass x3.6 and supply -40 %); the scan also
    # tries the plant file's values, from which the joint refit reaches the small
    # errors a plant file has
    nominal_point = {f.key: f.start for m in members if m.effect == "parameter_error"
                     for f in m.free if f.key in starts and len(members) > 1}
    free = tuple(replace(f, start=min(max(float(starts[f.key]), f.low), f.high))
                 if f.key in starts else f for m in members for f in m.free)
    scans = [] if scan is None else [scan] if isinstance(scan, Candidate) else list(scan)
    points = tuple(p for c in scans for p in c.grid_points())
    return Combined(name="+".join(m.name for m in members),
                    effect="+".join(m.effect for m in members), free=free, fixed=fixed,
                    scan_points=points,
                    needs_pressures=any(m.needs_pressures for m in members),
                    describe=" and ".join(m.name for m in members), members=tuple(members),
                    nominal_point=nominal_point,
                    neutral={k: v for m in members for k, v in m.neutral_values().items()},
                    subset_points=tuple(dict(p) for p in subsets))
