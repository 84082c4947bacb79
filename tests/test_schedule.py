"""The schedule that spends the budget: successor choice, tie-breaking, lineages, corpus energy."""

from __future__ import annotations

import random

from drivefuzz.search.schedule import Schedule, ScheduleConfig, pick_successor


def test_the_riskiest_member_is_picked():
    assert pick_successor([0.1, 0.7, 0.3], "risk", random.Random(0)) == 1


def test_ties_are_broken_by_the_seeded_rng_not_by_position():
    values = [0.2, 0.9, 0.9, 0.9, 0.1]
    picks = {pick_successor(values, "risk", random.Random(f"campaign-7/{k}")) for k in range(40)}
    assert picks == {1, 2, 3}  # every tied member gets chosen by some seed, no other member
    # and the same seed always gives the same choice
    assert len({pick_successor(values, "risk", random.Random("campaign-7/x")) for _ in range(5)}) == 1


def test_a_population_with_no_signal_keeps_the_parent():
    assert pick_successor([0.4, 0.4, 0.4], "risk", random.Random(0)) is None
    assert pick_successor([0.4], "risk", random.Random(0)) == 0  # one member is a choice, not a tie
    assert pick_successor([], "risk", random.Random(0)) is None


def test_random_mode_ignores_the_values():
    picks = {pick_successor([0.0, 0.0, 5.0, 0.0], "random", random.Random(k)) for k in range(60)}
    assert picks == {0, 1, 2, 3}


def _run_lineage(schedule: Schedule, values: list[float]) -> int:
    """Feed successive cycles' best values; return the cycles run before the lineage yielded."""
    schedule.start_lineage(random.Random(0))
    for n, v in enumerate(values, 1):
        if not schedule.cycle_done(v, f"corpus/{n}-{v}", None, found=False, continue_after_finding=False):
            return n
    return len(values)


def test_a_lineage_that_stops_improving_yields_after_patience_cycles():
    s = Schedule(ScheduleConfig(max_cycles=20, patience=3))
    assert _run_lineage(s, [1.0, 1.0, 1.0, 1.0, 1.0, 1.0]) == 4  # one improvement, then 3 without
    assert s.lineage is None


def test_a_lineage_that_keeps_improving_gets_more_cycles():
    s = Schedule(ScheduleConfig(max_cycles=8, patience=2))
    assert _run_lineage(s, [float(k) for k in range(1, 20)]) == 8  # up to max_cycles
    assert len(s.corpus) == 8  # every improving successor entered the corpus


def test_a_finding_ends_the_lineage_unless_the_campaign_continues():
    s = Schedule(ScheduleConfig(max_cycles=8, patience=3))
    s.start_lineage(random.Random(0))
    assert not s.cycle_done(1.0, "corpus/a", None, found=True, continue_after_finding=False)
    s.start_lineage(random.Random(0))
    assert s.cycle_done(1.0, "corpus/b", None, found=True, continue_after_finding=True)


def test_corpus_draws_prefer_risky_entries_that_were_picked_less():
    s = Schedule(ScheduleConfig(fresh_share=0.0))
    s.start_lineage(random.Random(0))
    for k, v in enumerate([0.1, 0.2, 5.0]):
        s.cycle_done(v, f"corpus/{k}", None, False, True)
    counts = {e.ref: 0 for e in s.corpus}
    rng = random.Random(3)
    for _ in range(300):
        counts[s.start_lineage(rng).start] += 1
    assert counts["corpus/2"] > counts["corpus/0"]
    assert all(c > 0 for c in counts.values())  # picks wear an entry's energy down: every one gets its turn


def test_the_state_round_trips_through_json():
    import json

    s = Schedule(ScheduleConfig())
    _run_lineage(s, [0.5, 0.7, 0.7])
    s.start_lineage(random.Random(1))
    again = Schedule.from_json(ScheduleConfig(), json.loads(json.dumps(s.to_json())), "risk")
    assert again.to_json() == s.to_json()


def test_a_lineage_that_found_something_gives_its_energy_away():
    s = Schedule(ScheduleConfig(fresh_share=0.0, found_penalty=3))
    s.start_lineage(random.Random(0))
    s.cycle_done(0.9, "corpus/a", None, False, False)
    s.cycle_done(0.95, "corpus/b", None, True, False)  # b found something: the lineage ends
    assert s.lineage is None
    assert [e.picks for e in s.corpus] == [3, 3]
    random_mode = Schedule(ScheduleConfig(), mode="random")
    random_mode.start_lineage(random.Random(0))
    random_mode.cycle_done(0.9, "corpus/a", None, True, False)
    assert [e.picks for e in random_mode.corpus] == [0]  # the baseline ignores what was found


# ------------------------------------------------------------------ behavioural coverage
CUT_IN = "straight|edge/none|vehicle|maneuver|left"
CROSS = "straight|junction/priority|vehicle|autopilot|right"


def test_a_rarely_met_situation_outweighs_a_common_one_of_equal_risk():
    s = Schedule(ScheduleConfig(), "risk")
    s.observe([CUT_IN] * 5, [])
    assert s.weight(CROSS) == 2.0  # never met: 1 + novelty
    assert s.weight(CUT_IN) == 1.0 + 1.0 / 6
    values = [0.5 * s.weight(CUT_IN), 0.5 * s.weight(CROSS)]
    assert pick_successor(values, "risk", random.Random(0)) == 1


def test_the_situation_of_a_finding_made_loses_weight():
    s = Schedule(ScheduleConfig(found_weight=0.5), "risk")
    s.observe([CUT_IN, CROSS], [CUT_IN])
    assert s.weight(CUT_IN) == 0.5 and s.weight(CROSS) > 1.0
    # a near miss in the found situation loses against a lesser risk in another one
    assert pick_successor([0.8 * s.weight(CUT_IN), 0.5 * s.weight(CROSS)], "risk", random.Random(0)) == 1


def test_new_coverage_enters_the_corpus_only_when_risky_and_new():
    s = Schedule(ScheduleConfig(corpus_risk=0.3), "risk")
    s.start_lineage(random.Random(0))
    assert s.is_new(CROSS, 0.4) and not s.is_new(CROSS, 0.1) and not s.is_new(None, 0.9)
    s.add_new("corpus/x", 0.8, "v1")
    s.observe([CROSS], [])
    assert not s.is_new(CROSS, 0.9)
    assert [(e.ref, e.lineage, e.hint) for e in s.corpus] == [("corpus/x", 0, "v1")]


def test_coverage_is_ignored_without_the_risk_feedback():
    for mode in ("random", "paper"):
        s = Schedule(ScheduleConfig(), mode)
        s.observe([CUT_IN], [CUT_IN])
        assert s.weight(CUT_IN) == 1.0 and s.weight(CROSS) == 1.0 and not s.is_new(CROSS, 1.0)


def test_coverage_survives_the_checkpoint():
    s = Schedule(ScheduleConfig(), "risk")
    s.observe([CUT_IN, CUT_IN, CROSS], [CROSS])
    back = Schedule.from_json(ScheduleConfig(), s.to_json(), "risk")
    assert back.seen == {CUT_IN: 2, CROSS: 1} and back.found == [CROSS]
    assert back.weight(CUT_IN) == s.weight(CUT_IN)
