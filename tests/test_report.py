"""``drivefuzz report`` and ``drivefuzz findings`` on a small real campaign (a speeding ADS, so it finds)."""

from __future__ import annotations

import json
import re
import shutil
import sqlite3
from html.parser import HTMLParser

import pytest
from click.testing import CliRunner

from drivefuzz.cli import main
from drivefuzz.campaign.fuzz import Campaign, FuzzConfig
from drivefuzz.scenario import AdsSpec
from drivefuzz.scenario.sumofiles import read_scenario

from conftest import ROOT

SEEDS = [ROOT / "seeds" / "town" / "005", ROOT / "seeds" / "town" / "000"]


@pytest.fixture(scope="module")
def campaign(tmp_path_factory):
    out = tmp_path_factory.mktemp("report") / "camp"
    cfg = FuzzConfig(cycles=2, population=2, max_execs=8, seed=3, strategy="all", continue_after_finding=True,
                     reproduce=1, isolate=False, ads=AdsSpec(name="ego", options={"fault": "speeding"}))
    Campaign(out, [read_scenario(p) for p in SEEDS], cfg).run()
    folders = sorted(f"{sub}/{p.name}" for sub in ("findings", "incidents") for p in (out / sub).iterdir()
                     if not p.name.startswith("."))
    assert any(f.startswith("findings/") for f in folders), "the speeding ADS found nothing"
    return out, folders


def _invoke(*args):
    result = CliRunner().invoke(main, list(map(str, args)))
    assert result.exit_code == 0, result.output
    return result.output


class _Tags(HTMLParser):
    """Every start tag with its attributes."""

    def __init__(self):
        super().__init__()
        self.tags: list[tuple[str, dict[str, str]]] = []

    def handle_starttag(self, tag, attrs):
        self.tags.append((tag, {k: v or "" for k, v in attrs}))


def _tags(html: str):
    p = _Tags()
    p.feed(html)
    return p.tags


def test_report_is_one_self_contained_file_with_a_card_per_signature(campaign, tmp_path):
    out, folders = campaign
    _invoke("report", out, "-o", tmp_path / "r" / "report.html")
    html = (tmp_path / "r" / "report.html").read_text()
    tags = _tags(html)
    assert not [a for t, a in tags if t in ("script", "link", "iframe", "object", "embed")]
    for tag, attrs in tags:
        for name in ("src", "href"):
            if name in attrs:
                assert attrs[name].startswith(("data:", "#")), (tag, attrs[name][:80])
    assert not re.search(r"url\(\s*['\"]?(https?:)?//", html), "CSS that fetches"
    imgs = [a["src"] for t, a in tags if t == "img"]
    assert any(s.startswith("data:image/gif;base64,") for s in imgs), "no animation"
    assert any(s.startswith("data:image/png;base64,") for s in imgs)
    cards = [a["data-folder"] for t, a in tags if "card" in a.get("class", "").split()]
    assert sorted(cards) == folders  # exactly one card per signature folder
    md = (tmp_path / "r" / "report.md").read_text()
    for folder in folders:
        assert f"`{folder}`" in md
    assert "speeding" in md and "data:" not in md
    n_findings = sum(f.startswith("findings/") for f in folders)
    # more than one finding: they are grouped into likely bugs, in both files
    assert ("## Likely bugs" in md and "<h2>Likely bugs</h2>" in html) is (n_findings > 1)
    if n_findings > 1:
        assert "| speeding/speeding: its own driving |" in md
    # every finding was shrunk during the campaign: its card and section show the minimal reproducer
    for folder in (f for f in folders if f.startswith("findings/")):
        assert f"drivefuzz replay {out / folder / 'minimal'}" in md
    assert html.count("minimal reproducer (") == sum(f.startswith("findings/") for f in folders)


def test_findings_rows_match_the_folders_and_are_numbered_by_first_hit(campaign):
    out, folders = campaign
    rows = json.loads(_invoke("findings", out, "--json", "--incidents"))
    assert sorted(r["folder"] for r in rows) == folders
    db = sqlite3.connect(out / "index.sqlite")
    first = dict(db.execute("SELECT COALESCE(finding, incident), MIN(exec_id) FROM executions "
                            "WHERE COALESCE(finding, incident) IS NOT NULL GROUP BY 1"))
    hits = dict(db.execute("SELECT COALESCE(finding, incident), COUNT(*) FROM executions GROUP BY 1"))
    for incident in (False, True):
        part = [r for r in rows if r["incident"] is incident]
        assert [r["number"] for r in part] == list(range(len(part)))
        assert [r["first_exec"] for r in part] == sorted(first[r["folder"]] for r in part)
        for r in part:
            assert r["first_exec"] == first[r["folder"]] and r["hits"] == hits[r["folder"]]
            assert r["replay"].startswith("drivefuzz replay ") and r["folder"] in r["replay"]
    text = _invoke("findings", out)
    assert all(r["folder"] in text for r in rows if not r["incident"])
    from drivefuzz.triage.attribute import RULES

    findings = [r for r in rows if not r["incident"]]
    assert all(r["rule"] in RULES for r in rows)
    if len(findings) > 1:  # the speeding ADS: every finding is its own driving, one likely bug
        classes = {(r["verdict"], r["fault"], r["rule"]) for r in findings}
        assert f"likely bugs: {len(classes)} " in text
        assert "speeding/speeding: its own driving" in text


def test_findings_group_by_the_rule_that_blamed_the_ego():
    from drivefuzz.triage.table import FindingRow, bug_groups

    def row(n, verdict, rule, hits=1, fault="ego"):
        return FindingRow(number=n, folder=f"findings/{n}", signature=str(n), label="x", verdict=verdict, fault=fault,
                          reason="x", hits=hits, reproduced=None, runs=None, robust=None, first_exec=n, first_key="-",
                          first_time_s=None, sim_time_s=None, replay="-", rule=rule)

    rows = [row(0, "red_light/red", "own_driving"), row(1, "collision/vehicle", "failed_to_yield", hits=3),
            row(2, "collision/vehicle", "struck"), row(3, "collision/vehicle", "failed_to_yield"),
            row(4, "collision/vehicle", "", hits=2), row(5, "collision/vehicle", "unknown-rule"),
            row(6, "collision/vehicle", "struck", fault="unclear")]
    groups = bug_groups(rows)
    assert [[r.number for r in g.rows] for g in groups] == [[1, 3], [4, 5], [0], [2], [6]]
    # a finding the careful driver's replay could not settle is not the ego's yet: its own group, and said so
    assert groups[4].title == "collision/vehicle: it struck another road user (fault: unclear)"
    assert groups[0].title == "collision/vehicle: it did not yield where its link must yield" and groups[0].hits == 4
    assert groups[1].title == "collision/vehicle"  # verdicts filed before rules were recorded: oracle and kind
    assert groups[0].line().endswith("(#1 #3)")


def test_numbering_follows_the_index_not_the_folder_names(campaign, tmp_path):
    out, folders = campaign
    if len(folders) < 2:
        pytest.skip("one signature: nothing to order")
    copy = tmp_path / "camp"
    shutil.copytree(out, copy)
    db = sqlite3.connect(copy / "index.sqlite")
    db.execute("UPDATE executions SET exec_id = 100000 - exec_id")  # the last execution is now the first
    db.commit()
    db.close()
    before = json.loads(_invoke("findings", out, "--json", "--incidents"))
    after = json.loads(_invoke("findings", copy, "--json", "--incidents"))
    db = sqlite3.connect(copy / "index.sqlite")
    first = dict(db.execute("SELECT COALESCE(finding, incident), MIN(exec_id) FROM executions GROUP BY 1"))
    for incident in (False, True):
        names = [r["folder"] for r in after if r["incident"] is incident]
        assert names == sorted(names, key=first.get)
    assert [r["folder"] for r in before] != [r["folder"] for r in after] or len(
        {r["folder"] for r in before if not r["incident"]}) < 2


def test_a_damaged_folder_still_gets_its_card_and_the_cap_is_said(campaign, tmp_path):
    out, folders = campaign
    copy = tmp_path / "camp"
    shutil.copytree(out, copy)
    damaged = next(f for f in folders if f.startswith("findings/"))
    shutil.rmtree(copy / damaged / "trace")
    (copy / damaged / "hits.json").unlink(missing_ok=True)
    _invoke("report", copy, "--no-animation")
    html = (copy / "report.html").read_text()
    cards = [a["data-folder"] for t, a in _tags(html) if "card" in a.get("class", "").split()]
    assert sorted(cards) == folders
    assert "no trace" in html
    _invoke("report", copy, "--max-cards", "1", "--no-animation")
    html = (copy / "report.html").read_text()
    assert len([a for t, a in _tags(html) if "card" in a.get("class", "").split()]) == 1
    assert f"{len(folders) - 1} more card(s) left out" in html


def test_not_a_campaign_is_an_input_error(tmp_path):
    for cmd in ("report", "findings"):
        result = CliRunner().invoke(main, [cmd, str(tmp_path)])
        assert result.exit_code == 2 and "not a campaign directory" in result.output


def test_fuzz_writes_the_report_at_the_end_when_asked(tmp_path):
    out = tmp_path / "camp"
    result = CliRunner().invoke(main, ["fuzz", str(ROOT / "networks" / "town.net.xml"), "--seeds",
                                       str(ROOT / "seeds" / "town"), "--max-execs", "3", "--cycles", "1",
                                       "--population", "2", "--report", "-o", str(out)])
    assert result.exit_code in (0, 1), result.output
    assert f"report: {out / 'report.html'} and {out / 'report.md'}" in result.output
    assert "<html" in (out / "report.html").read_text() and (out / "report.md").read_text().startswith("# drivefuzz report")
