"""The ADS's record of its decisions on a finding's card (drivefuzz.triage.ads_info): the CommonRoad adapter's
planning cycles up to the event, and any other ADS's scalar entries as they are."""

from __future__ import annotations

from drivefuzz.triage.ads_info import LAST_CYCLES, summarize, to_html, to_markdown

CYCLES = {"t": [0.0, 0.3, 0.6, 0.9, 1.2], "outcome": ["plan", "plan", "none", "raised", "plan"],
          "error": ["", "", "", "TypeError: boom <b>", ""], "wall": [False, True, True, False, False],
          "v_des": [5.0, 4.5, 4.0, 3.5, 3.0], "v_plan_max": [5.2, 4.6, None, None, 3.1]}


def test_the_cycles_up_to_the_event_are_counted_and_the_first_without_a_plan_is_named():
    s = summarize({"adapter": "X", "horizon_steps": 30, "cycles": CYCLES}, t_event=0.95)
    assert s.lines[0] == "adapter X, horizon_steps 30"
    assert s.lines[1] == "4 planning cycles up to the event: 2 plan, 1 none, 1 raised; stop-line wall set in 2"
    assert s.lines[2] == "first cycle without a plan: t = 0.60 s, none"
    assert [r[0] for r in s.rows] == ["0.00", "0.30", "0.60", "0.90"] and len(s.rows) <= LAST_CYCLES
    assert s.rows[3] == ("0.90", "raised", "3.50", "", "no", "TypeError: boom <b>")
    html = to_html(s)
    assert "TypeError: boom &lt;b&gt;" in html and "<b>" not in html.replace("<b>the ADS", "")
    md = to_markdown(s)
    assert md[0].startswith("- the ADS's decisions") and any(line.startswith("| 0.90 | raised") for line in md)


def test_no_record_no_section_and_a_record_without_cycles_is_listed_as_it_is():
    assert summarize(None, 1.0) is None and summarize({}, 1.0) is None
    assert to_html(None) == "" and to_markdown(None) == []
    s = summarize({"mode": "cautious", "nested": {"a": 1}}, None)
    assert s.lines == ["mode cautious"] and s.rows == []
