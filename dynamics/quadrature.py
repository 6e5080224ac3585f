"""Cumulative integrals of closed-form rates at output rows, to the integrands' own accuracy: the works of a
closed-form run from its exact powers (docs/stability.md, 'The closed form's works').

The rows' gaps are cut at the breaks (where a rate jumps: the run's mode changes) and into panels of at most
`widest`. Each panel is integrated by the 5-point Gauss-Lobatto rule (exact to degree 7; Abramowitz & Stegun
25.4.32) and, for its error, by Simpson's rule on three of the same nodes (its ends and middle); a panel where the
two differ by more than its share of the tolerance is replaced by its halves, all such panels at once, until every
panel holds or after `LEVELS` halvings. Both rules hold the panel's ends among their nodes: a kink no break names
(a friction force reversing with the slip: the power's |slip|) between an end and the next node is seen by both
with different weights. With Gauss-Legendre's nodes, all inside, a kink before the first node is extrapolated
over by a rule and by its halves alike (their difference nil, both a micro-joule off).

`split_gaps` cuts the gaps between instants into equal parts: the panels here, and the instants a closed form's
contact switches are searched on (thermal/exact.py).
"""
from __future__ import annotations

from typing import Callable

import numpy as np

#: the 5-point Gauss-Lobatto rule on [-1, 1] and Simpson's on its nodes 0, 2 and 4: nodes and weights
_X = np.array([-1.0, -np.sqrt(3.0 / 7.0), 0.0, np.sqrt(3.0 / 7.0), 1.0])
_W = np.array([1.0 / 10.0, 49.0 / 90.0, 32.0 / 45.0, 49.0 / 90.0, 1.0 / 10.0])
_SIMPSON = np.array([1.0 / 3.0, 0.0, 4.0 / 3.0, 0.0, 1.0 / 3.0])
#: at most this many halvings of a panel (a jump the breaks do not name is then 2^-LEVELS of its panel wide)
LEVELS = 40
#: the tolerance per unit time, relative to the largest rate seen (the integrals' error below TOLERANCE max|rate| T)
TOLERANCE = 1e-10
#: at most this many times `most` panels integrated in all (the first ones and their halves)
REFINED = 3
#: a panel's end at a break is read this fraction of the first panel there inside it (`_rules`)
INSIDE = 1e-7
#: a panel's integrals are known to this many ulps of their magnitude's integral (the sum of its nodes' products),
#: where the rates themselves are exact to round-off
ROUNDOFF = 64 * np.finfo(float).eps


def cumulative_integrals(rates: Callable[[np.ndarray], dict[str, np.ndarray]], rows: np.ndarray,
                         breaks: np.ndarray, widest: float, most: int, at_rows: dict | None = None
                         ) -> tuple[dict[str, np.ndarray], np.ndarray]:
    """({name: its integral from rows[0] to each row}, the error estimate of their sum at each row: the
    accumulated |Lobatto - Simpson| of its panels). rates(instants): each named rate at the instants (any order);
    breaks: instants where a rate may jump (those outside the rows' span ignored); widest: the widest panel; most:
    at most this many panels at the start (wider ones where the rows' span needs more), and REFINED times as many
    integrated in all (the halving ends there). at_rows: {name: the rate at the rows} where read already (the
    table's own columns: a panel's ends are mostly rows)."""
    rows = np.asarray(rows, dtype=float)
    known = None if at_rows is None else (rows, at_rows)
    edges, at_break = _edges(rows, np.asarray(breaks, dtype=float), widest, most)
    lo, hi = edges[:-1], edges[1:]
    inside = np.stack([at_break[:-1], at_break[1:]], axis=1)       # a panel's ends read just inside it
    reach = INSIDE * (hi - lo)         # how far inside: a fraction of the first panel's width, kept by its halves
    gap = np.clip(rows.searchsorted(lo, side="right") - 1, 0, len(rows) - 2)     # the rows' gap each panel is in
    totals: dict[str, np.ndarray] = {}
    error = np.zeros(len(rows) - 1)
    scale = negligible = None
    spent = 0                          # panels integrated so far
    for level in range(LEVELS + 1):
        if not len(lo):
            break
        five, three, magnitude = _rules(rates, lo, hi, inside, reach, known if level == 0 else None)
        names = list(five)
        if not names:
            break
        if scale is None:
            scale = max(float(np.max(magnitude[name] / (hi - lo), initial=0.0)) for name in names)
            # a panel's error below this is negligible: `most` such panels together stay below the tolerance
            # (where the rates are differences of far larger terms, their round-off exceeds TOLERANCE scale h)
            negligible = TOLERANCE * scale * (rows[-1] - rows[0]) / max(most, 1)
        differs = np.max([np.abs(five[name] - three[name]) for name in names], axis=0)
        # the tolerance, or the panel's own round-off where that is more (a panel refined to a few ulps)
        floor = np.maximum(ROUNDOFF * np.max([magnitude[name] for name in names], axis=0), negligible)
        done = ~(differs > np.maximum(TOLERANCE * scale * (hi - lo), floor)) | (level == LEVELS)
        spent += len(lo)
        if spent + 2 * (~done).sum() > REFINED * most:      # the bound on the resources: every panel taken as it is
            done[:] = True
        for name in names:
            np.add.at(totals.setdefault(name, np.zeros(len(rows) - 1)), gap[done], five[name][done])
        np.add.at(error, gap[done], np.abs(sum(five.values()) - sum(three.values()))[done])
        split = ~done
        mid = 0.5 * (lo + hi)
        lo, hi, gap = (np.concatenate([lo[split], mid[split]]), np.concatenate([mid[split], hi[split]]),
                       np.concatenate([gap[split], gap[split]]))
        inside = np.concatenate([inside[split] & [True, False], inside[split] & [False, True]])
        reach = np.minimum(np.concatenate([reach[split], reach[split]]), 0.25 * (hi - lo))
    cumulative = {name: np.concatenate([[0.0], np.cumsum(v)]) for name, v in totals.items()}
    return cumulative, np.concatenate([[0.0], np.cumsum(error)])


def _rules(rates, lo: np.ndarray, hi: np.ndarray, inside: np.ndarray, reach: np.ndarray, known: tuple | None = None
           ) -> tuple[dict, dict, dict]:
    """Each rate's integral over every panel [lo, hi] by the 5-point Gauss-Lobatto rule, by Simpson's on the same
    nodes, and its magnitude's by the first: three {rate: per panel}, from one call of `rates` for all nodes but
    those `known` gives ((instants, {rate: its values there})).
    inside: per panel, whether its start and its end are breaks, read `reach` inside the panel there (its one-sided
    limit: the rate jumps at a break, and the instant itself has one side's value, which for the panel on the
    other side is an error of the jump times the end's weight however fine the panel; a closed form switches
    within round-off of its listed instant, 1e-11 s on a chain's stop, so the reach does not shrink with the
    panel's halves)."""
    half, mid = 0.5 * (hi - lo), 0.5 * (hi + lo)
    at = mid[:, None] + half[:, None] * _X
    at[:, 0] = np.where(inside[:, 0], lo + reach, at[:, 0])
    at[:, -1] = np.where(inside[:, 1], hi - reach, at[:, -1])
    # each instant read once (a panel's end is its neighbour's start), and not at all where it is given (`known`)
    instants, where = np.unique(at.ravel(), return_inverse=True)
    ask = np.ones(len(instants), dtype=bool)
    if known is not None:
        pos = np.clip(known[0].searchsorted(instants), 0, len(known[0]) - 1)
        hit = known[0][pos] == instants
        ask = ~hit
    asked = rates(instants[ask]) if ask.any() else {name: np.zeros(0) for name in known[1]}
    got = {}
    for name, v in asked.items():
        full = np.empty(len(instants))
        full[ask] = np.broadcast_to(np.asarray(v, dtype=float), int(ask.sum()))
        if known is not None:
            full[hit] = np.broadcast_to(np.asarray(known[1][name], dtype=float), known[0].shape)[pos[hit]]
        got[name] = full[where].reshape(at.shape)
    return ({name: half * (v @ _W) for name, v in got.items()}, {name: half * (v @ _SIMPSON) for name, v in got.items()},
            {name: np.abs(half) * (np.abs(v) @ _W) for name, v in got.items()})


def _edges(rows: np.ndarray, breaks: np.ndarray, widest: float, most: int) -> tuple[np.ndarray, np.ndarray]:
    """(the rows and the breaks inside their span, sorted, each gap between them cut into equal panels of at most
    `widest` (wider where that would make more than `most`), whether each is a break)."""
    inside = breaks[(breaks > rows[0]) & (breaks < rows[-1])]
    points = np.unique(np.concatenate([rows, inside]))
    edges, first = split_gaps(points, widest, most)
    at_break = np.zeros(len(edges), dtype=bool)
    at_break[first] = np.isin(points, inside)
    return edges, at_break


def split_gaps(points: np.ndarray, widest: float, most: int) -> tuple[np.ndarray, np.ndarray]:
    """(instants, each point's position among them): the increasing `points` with each gap between them cut into
    equal parts of at most `widest` (wider where that would make more than `most` parts), the points themselves
    kept exactly."""
    width = np.diff(points)
    parts = np.ceil(width / widest) if widest > 0 else np.ones(len(width))
    if parts.sum() > most:
        parts = np.ceil(parts * (most / parts.sum()))
    parts = np.maximum(parts, 1).astype(np.int64)
    first = np.concatenate([[0], np.cumsum(parts)])
    piece = np.repeat(np.arange(len(parts)), parts)
    within = np.arange(first[-1]) - first[piece]
    instants = np.concatenate([points[piece] + width[piece] * (within / parts[piece]), points[-1:]])
    instants[first] = points
    return instants, first
