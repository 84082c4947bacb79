"""Regression mode: a faulty ADS's findings re-run against the clean one are fixed, against itself they still
fail; the JUnit file parses, with one test case per finding."""

from __future__ import annotations

import xml.etree.ElementTree as ET

import pytest
from click.testing import CliRunner

from drivefuzz.campaign.fuzz import Campaign, FuzzConfig
from drivefuzz.cli import main
from drivefuzz.scenario import AdsSpec, SimOptions


@pytest.fixture(scope="module")
def archive(tmp_path_factory, town):
    from drivefuzz.scenario import Mission, Scenario

    from conftest import TOWN

    seed = Scenario(network=str(TOWN), sim=SimOptions(time_limit=40.0),
                    mission=Mission(start_lane=town.drive_lane("A0B0"), start_pos=10.0, goal_edge="B0C0", goal_pos=40.0))
    out = tmp_path_factory.mktemp("regress") / "camp"
    cfg = FuzzConfig(cycles=2, population=2, max_execs=6, continue_after_finding=True, reproduce=0, shrink=0,
                     ads=AdsSpec(name="ego", options={"fault": "speeding"}))
    found = Campaign(out, [seed], cfg).run()
    assert any(f.misbehavior.oracle == "speeding" for f in found)
    return out, found


def test_the_faults_findings_are_fixed_by_the_clean_ads(archive, tmp_path):
    out, found = archive
    junit = tmp_path / "ci" / "regress.xml"
    result = CliRunner().invoke(main, ["regress", str(out), "--ads", "ego", "--junit", str(junit)])
    speeding = [f for f in found if f.misbehavior.oracle == "speeding"]
    others = [f for f in found if f.misbehavior.oracle != "speeding"]
    assert result.exit_code == (1 if others else 0), result.output
    rows = [line.split() for line in result.output.splitlines()]
    for f in speeding:
        assert ["fixed", "speeding/speeding", "no", "misbehaviour", "(goal_reached)", str(f.path)] in rows
    suite = ET.parse(junit).getroot()
    assert suite.tag == "testsuite" and int(suite.get("tests")) == len(found)
    cases = suite.findall("testcase")
    assert len(cases) == len(found)
    failed = [c for c in cases if c.find("failure") is not None]
    assert int(suite.get("failures")) == len(failed) == len(others)
    assert all("speeding" not in c.get("name").split(":")[0] for c in failed)


def test_against_the_faulty_ads_they_still_fail(archive, tmp_path):
    out, found = archive
    finding = next(f for f in found if f.misbehavior.oracle == "speeding")
    junit = tmp_path / "regress.xml"
    result = CliRunner().invoke(main, ["regress", str(finding.path), "--ads", "ego", "--ads-option", "fault=speeding",
                                       "--junit", str(junit)])
    assert result.exit_code == 1, result.output
    assert "1 finding(s): 1 still failing, 0 failing differently, 0 fixed" in result.output
    (case,) = ET.parse(junit).getroot().findall("testcase")
    assert case.find("failure").get("type") == "still-failing"


def test_not_an_archive_is_an_input_error(tmp_path):
    result = CliRunner().invoke(main, ["regress", str(tmp_path), "--ads", "ego"])
    assert result.exit_code == 2
    assert str(tmp_path) in result.output and "neither a finding folder nor a campaign directory" in result.output
