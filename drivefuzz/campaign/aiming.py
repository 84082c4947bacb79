"""Which interaction-coverage cells a fuzz job aims the mutator at (:mod:`drivefuzz.search.aim` builds for them).

A campaign's seed jobs run in parallel, so every reachable cell falls to one of them (:func:`share_cells`, by what
the mutator can aim at on each seed's mission: :func:`can_aim`); a job aims at the cells nobody has reached first
(what the other jobs reached in their earlier lineages: :class:`PeerView`), its share of them, then its seed's
others, and gives up on a cell its aimed builds keep missing (:func:`aim_cells`, :func:`count_misses`). The shares
are a pure function of the manifest's seeds and the misses of the job's own results; the other jobs' cells are
recorded in its journal. So a resumed job aims as the first run did.
"""

from __future__ import annotations

import random
from pathlib import Path
from typing import Any, Callable

from drivefuzz.search.aim import BLOCKED_LANE
from drivefuzz.search.aim_place import SHIFTED_START
from drivefuzz.storage import read_new_lines
from drivefuzz.triage.coverage import aimed_cell

#: a job stops aiming at a cell once this many of its aimed builds missed it (while it has other cells to aim at)
AIM_MISSES = 3
#: the misses of aimed lane changes around a stopped car, kept with the cells' (:func:`aim_cells`)
BLOCKED_MISS = "lane_change around a stopped car"
#: the misses of aimed lane changes on a start on another lane (:func:`aim_cells`)
SHIFTED_MISS = "lane_change on a start on another lane"


_REACH: dict[tuple, dict[str, frozenset[str]]] = {}


def seed_places(rmap, seed_sc) -> dict[str, frozenset[str]]:
    """The interaction-coverage cells the seed's network and route offer, with the junctions where the route
    offers each (:func:`drivefuzz.triage.coverage.reachable_places`; cached per process)."""
    from drivefuzz.triage.coverage import reachable_places

    key = (str(rmap.path), seed_sc.mission.start_lane, seed_sc.mission.start_pos, seed_sc.mission.goal_edge)
    if key not in _REACH:
        _REACH[key] = reachable_places(rmap, [seed_sc])
    return _REACH[key]


def seed_reachable(rmap, seed_sc) -> list[str]:
    """The interaction-coverage cells the seed's network and route offer (sorted keys; cached per process)."""
    return list(seed_places(rmap, seed_sc))


def share_cells(reaches: list[list[str]], builds: Callable[[int, str], bool] | None = None,
                places: list[dict[str, frozenset[str]]] | None = None) -> list[list[str]]:
    """Each seed job's share of the campaign's reachable cells: every cell goes to one of the seeds that offer it
    (``reaches[i]``: seed i's cells), the cells fewest seeds offer first, each to the offering seed with the
    smallest share so far (the lower index on a tie) among those whose mission the mutator can aim at it
    (``builds(i, cell)``, :func:`can_aim`; where none can, among all). A pure function of the seeds, so every job
    computes the same shares alone, without hearing from the others (they run in parallel: a campaign-wide count
    of what was reached would make a job's draws depend on the others' timing). Without it every job aims at all
    its seed's cells, and eight town jobs aim at the same ~80 unreached cells, each a few times.

    With ``places`` (seed i's cells with the junctions where its route offers each, :func:`seed_places`), a cell
    that seeds offer at different junctions goes also to a seed that can aim at it at a junction none of the
    cell's seeds so far has, until every such junction has one: a cell is a class of encounters, and one junction
    of it is not the others (on town a car from the left at a yield sign is offered by seed 001 at D1 and by seed
    002 at B0; it went to seed 001 alone, was reached at D1, and never aimed at B0, where the hidden fault
    ``crossing_left_blind`` collides)."""
    offered: dict[str, list[int]] = {}
    for i, cells in enumerate(reaches):
        for c in cells:
            offered.setdefault(c, []).append(i)
    shares: list[list[str]] = [[] for _ in reaches]
    holder: dict[str, int] = {}
    rarest_first = sorted(offered, key=lambda c: (len(offered[c]), c))
    for c in rarest_first:
        order = sorted(offered[c], key=lambda i: (len(shares[i]), i))
        i = holder[c] = next((i for i in order if builds is None or builds(i, c)), order[0])
        shares[i].append(c)
    if places is not None:
        for c in rarest_first:
            seen = set(places[holder[c]].get(c, ()))
            for i in sorted(offered[c], key=lambda i: (len(shares[i]), i)):
                new = places[i].get(c, frozenset()) - seen
                if i != holder[c] and new and (builds is None or builds(i, c)):
                    shares[i].append(c)
                    seen |= new
    return [sorted(s) for s in shares]


def shares_by_place(rmap, seeds: list, places: list[dict[str, frozenset[str]]]) -> list[list[str]]:
    """:func:`share_cells` of ``seeds`` by :func:`can_aim`, each cell at each of its junctions (``places[i]``:
    :func:`seed_places` of seed i, empty for a seed on another network)."""
    return share_cells([list(p) for p in places], lambda i, c: can_aim(rmap, seeds[i], c, i), places)


#: draws of an aimed build per (seed, cell) before :func:`can_aim` says no
AIM_TRIES = 3
_CAN_AIM: dict[tuple, bool] = {}
_MUTATORS: dict[str, Any] = {}  # one Mutator per network, for can_aim


def can_aim(rmap, seed_sc, cell: str, index: int) -> bool:
    """Whether the mutator, without a profile of any ADS (a job knows only its own seed's run), can aim at ``cell``
    on the mission of seed ``index`` in :data:`AIM_TRIES` draws (1-2 ms each; cached per process). On town a
    quarter of the (seed, cell) pairs the derivation offers it cannot (the derivation over-approximates): seed
    000's one light, C2, lets no car from the right through when the ego comes; seed 004's lights do. Sharing by
    offer alone gave 54 of town's 185 cells to a seed that cannot aim at them, now 9, those no seed can."""
    from drivefuzz.search.aim import aimed
    from drivefuzz.search.mutate import Mutator

    key = (str(rmap.path), seed_sc.content_hash(), cell, index)
    if key not in _CAN_AIM:
        mut = _MUTATORS.get(str(rmap.path))
        if mut is None:  # one per network and process (setdefault would build a new one on every call)
            mut = _MUTATORS[str(rmap.path)] = Mutator(rmap)
        _CAN_AIM[key] = any(aimed(mut, seed_sc, cell, random.Random(f"share/{index}/{cell}/{k}"))[0].scenario
                            is not seed_sc for k in range(AIM_TRIES))
    return _CAN_AIM[key]


def aim_cells(reach, reached, misses: dict[str, int], own=(), elsewhere=(),
              can: Callable[[str], bool] | None = None, handed=()) -> list[str]:
    """The cells a job aims at: its share of the campaign's cells (``own``, :func:`share_cells`) not reached yet
    by it; when it has reached them all, its seed's other reachable cells not reached yet. Less, in both, those
    its aimed builds have missed :data:`AIM_MISSES` times (the aims spread over the others), and every lane-change
    cell once that many lane changes around a stopped car ended with the ego still in its lane (an ADS that waits
    behind a stopped car, as the reference ADS does, makes each of them one more execution of the same finding);
    all unreached ones when every one has.

    ``elsewhere``: the cells the campaign's other jobs have reached (:class:`PeerView`). The cells nobody has
    reached come first, the job's share of them, then its seed's others; then its share of those another job
    reached (at another junction, say). On two 1,000-execution town campaigns without it, 210-237 of some 420
    aims went at a cell another job had already reached (`docs/coverage.md`, fourteenth session). ``can(cell)``
    (:func:`can_aim` on the job's seed) keeps the seed's other cells nobody reached to those the mutator can build
    on its mission: an aim it cannot build becomes an ordinary mutation. Without ``elsewhere`` (a job's first
    lineage) the order is the one before: its share, then its seed's others."""
    unreached = [c for c in reach if c not in reached]
    # a cell another job gave up on (``handed``: :meth:`PeerView.given_up`) becomes this job's too where its seed
    # offers it and the mutator can build it on its mission: its holder's mission may offer it only in a form that
    # no aim meets (the interchange's car from the left at amber, held by seed 004: 0 of 4 lab draws met it there, 3
    # of 7 on seeds 001 and 007, which aimed at it once a campaign)
    own = set(own) | {c for c in handed if c in reach and (can is None or can(c))}
    # a start on another lane makes any ADS change lanes, but each such cell it misses costs an execution: past
    # AIM_MISSES of them the job leaves the lane-change cells (the shifted start on town's five seeds without a lane
    # change of their own cost finding power: crossing_left_blind in 5 of 10 campaigns, 4 of 5 without any shifted
    # start; with this rule still 3 of 5; with a cell aimed at each of its junctions, 8 of 10: docs/coverage.md)
    waits = misses.get(BLOCKED_MISS, 0) >= AIM_MISSES or misses.get(SHIFTED_MISS, 0) >= AIM_MISSES
    nobody = [c for c in unreached if c not in elsewhere]
    others = [c for c in nobody if c in own or can is None or can(c)] if elsewhere else nobody
    for cells in ([c for c in nobody if c in own], others, [c for c in unreached if c in own], unreached):
        aim = [c for c in cells if misses.get(c, 0) < AIM_MISSES and not (waits and c.endswith("|lane_change"))]
        if aim:
            return aim
    return unreached


class PeerView:
    """What the campaign's other seed jobs on the same network have reached: the cells of their journals'
    executions in lineages before the one a job is in (their seed runs too), nothing in its first lineage. Run in
    turns (``--jobs 1``, one lineage of each job per turn) those lineages are over when a job begins one, and the
    view is a pure function of the campaign's seeds; on Dask the jobs run at their own pace and a job sees what
    the others had journalled by then. Either way the job records the view in its journal when the lineage begins
    (:func:`drivefuzz.campaign.job.peer_views`), so a resume aims as the first run did. (Waiting on Dask for the
    others' lineages to end would make the view timing-free, at a cost: estimated from two town campaigns' lineage
    times, 15-56 % more wall time with 4-8 workers for 8 seeds.) Journals are read on from where the last read ended."""

    def __init__(self, journals: list[Path]):
        self.journals = journals
        self._offsets = [0] * len(journals)
        self._by_lineage: dict[int, set[str]] = {}
        self._misses: dict[int, list[dict[str, int]]] = {}  # per lineage, per peer: its aims that missed, by cell

    def reached(self, lineage: int) -> frozenset[str]:
        """The cells the peers reached in their lineages before ``lineage`` (none for lineage 0)."""
        if lineage <= 0:
            return frozenset()
        self._read()
        return frozenset().union(*(cells for n, cells in self._by_lineage.items() if n < lineage))

    def given_up(self, lineage: int) -> frozenset[str]:
        """The cells a peer stopped aiming at in its lineages before ``lineage``: its aimed builds missed each
        :data:`AIM_MISSES` times (none for lineage 0). Another seed's mission may offer such a cell in a form its
        aims hit (:func:`aim_cells` takes them into the job's share)."""
        if lineage <= 0:
            return frozenset()
        self._read()
        out: set[str] = set()
        for k in range(len(self.journals)):
            total: dict[str, int] = {}
            for n, per_peer in self._misses.items():
                if n < lineage:
                    for cell, count in per_peer[k].items():
                        total[cell] = total.get(cell, 0) + count
            out |= {c for c, count in total.items() if count >= AIM_MISSES and ":" in c}
        return frozenset(out)

    def _read(self) -> None:
        for k, path in enumerate(self.journals):
            recs, self._offsets[k] = read_new_lines(path, self._offsets[k])
            for rec in recs:
                if isinstance(rec, dict) and rec.get("event") == "end" and isinstance(rec.get("lineage"), int) \
                        and isinstance(rec.get("cells"), list):
                    self._by_lineage.setdefault(rec["lineage"], set()).update(
                        c for c in rec["cells"] if isinstance(c, str))
                    if isinstance(rec.get("mutation"), str):
                        per_peer = self._misses.setdefault(rec["lineage"], [{} for _ in self.journals])
                        count_misses(per_peer[k], [rec])


def count_misses(misses: dict[str, int], recs: list[dict[str, Any]]) -> None:
    """Add to ``misses`` the members of a cycle that were aimed at a cell (their ``mutation`` begins ``aim <cell>:``)
    and did not reach it, and under :data:`BLOCKED_MISS` the lane changes around a stopped car in which the ego
    changed no lane. Counted at the end of each cycle and kept in the checkpoint, as the schedule's cells are,
    so a resumed job aims as the first run did."""
    for rec in recs:
        cell = aimed_cell(rec)
        cells = rec.get("cells") or ()
        if cell and cell not in cells:
            misses[cell] = misses.get(cell, 0) + 1
            if cell.endswith("|lane_change") and f": {BLOCKED_LANE}:" in rec.get("mutation", "") \
                    and not any(c.endswith("|lane_change") for c in cells):
                misses[BLOCKED_MISS] = misses.get(BLOCKED_MISS, 0) + 1
            if cell.endswith("|lane_change") and f": {SHIFTED_START} " in rec.get("mutation", ""):
                misses[SHIFTED_MISS] = misses.get(SHIFTED_MISS, 0) + 1


#: the modules whose code decides what can be aimed at: any edit to one of them invalidates cached shares
_AIM_CODE = ("campaign/aiming.py", "search/aim.py", "search/aim_place.py", "search/catalogue.py",
             "search/programs.py", "search/fairness.py", "search/placement.py", "search/mutate.py",
             "triage/coverage.py", "scenario/roadmap.py", "scenario/model.py", "scenario/signals.py",
             "scenario/conflicts.py")


def cached_shares(rmap, seeds: list) -> list[list[str]]:
    """:func:`share_cells` of ``seeds`` (all on ``rmap``'s network) by :func:`can_aim`, through the disk cache of
    network-derived data (:mod:`drivefuzz.netcache`, keyed by the network's bytes, the seeds' contents and the
    code of the aiming modules): a campaign on the same seeds does not build the 200-500 aimed draws again
    (1-2 s, which a 60-execution campaign spent in start-up). A missing or unreadable entry is computed again."""
    import hashlib
    from pathlib import Path

    import numpy as np

    from drivefuzz import netcache

    root = Path(__file__).resolve().parent.parent
    missions = hashlib.sha256("|".join(sc.content_hash() for sc in seeds).encode()).hexdigest()[:24]
    try:
        code = hashlib.sha256("".join(netcache.file_sha256(root / m) for m in _AIM_CODE).encode()).hexdigest()[:16]
    except OSError:
        code = None
    key = netcache.entry_key(rmap.path, __file__, "aim-shares", missions, code) if code else None
    got = netcache.load(key)
    if got is not None and "cells" in got and got["cells"].dtype.kind == "U" and got["cells"].ndim == 1:
        shares: list[list[str]] = [[] for _ in seeds]
        try:
            for line in got["cells"].tolist():
                i, cell = line.split("\t", 1)
                shares[int(i)].append(cell)
            return shares
        except (ValueError, IndexError):
            pass
    shares = shares_by_place(rmap, seeds, [seed_places(rmap, sc) for sc in seeds])
    netcache.store(key, {"cells": np.array([f"{i}\t{c}" for i, cells in enumerate(shares) for c in cells] or [""])})
    return shares

