"""Export to OpenSCENARIO: the .xosc validates against the standard's schema, carries every traced body
and the failure's timing, and its road (.xodr) lies in the trace's coordinates."""

from __future__ import annotations

import xml.etree.ElementTree as ET

import pytest
import xmlschema
from click.testing import CliRunner

from drivefuzz.campaign.fuzz import Campaign, FuzzConfig
from drivefuzz.cli import main
from drivefuzz.scenario import Actor, AdsSpec, Mission, Scenario, SimOptions, Weather
from drivefuzz.sim.trace import Trace
from drivefuzz.triage.export import validate_openscenario

from conftest import TOWN


@pytest.fixture(scope="module")
def finding(tmp_path_factory):
    seed = Scenario(network=str(TOWN), ads=AdsSpec(name="ego", options={"fault": "ignore_pedestrians"}),
                    mission=Mission(start_lane="A0B0_1", start_pos=10.0, goal_edge="B0C0", goal_pos=40.0),
                    actors=(Actor(id="p0", kind="pedestrian", nav="linear", start_lane="A0B0_0", start_pos=60.0,
                                  speed=0.3, dest_xy=(68.4, 7.4)),),
                    weather=Weather(fog=40.0, rain=20.0), sim=SimOptions(time_limit=30.0))
    out = tmp_path_factory.mktemp("export") / "camp"
    cfg = FuzzConfig(cycles=1, population=1, max_execs=1, reproduce=0, shrink=0, ads=seed.ads)
    (found, *_rest) = Campaign(out, [seed], cfg).run()  # the seed's own run collides
    assert found.misbehavior.oracle == "collision"
    return found


def test_the_export_validates_against_the_openscenario_schema(finding, tmp_path):
    result = CliRunner().invoke(main, ["export", str(finding.path), "--to", "openscenario", "-o", str(tmp_path)])
    assert result.exit_code == 0, result.output
    xosc = tmp_path / f"{finding.path.name}.xosc"
    validate_openscenario(xosc)
    root = ET.parse(xosc).getroot()
    trace = Trace.load(finding.path / "trace")
    names = {o.get("name") for o in root.iter("ScenarioObject")}
    assert names == {"ego", *trace.actors.ids}
    assert root.find("RoadNetwork/LogicFile").get("filepath") == f"{finding.path.name}.xodr"
    assert root.find(".//Fog").get("visualRange") == "66"  # 100 m * (1 - 0.85 * 0.4)
    for poly in root.iter("Polyline"):
        times = [float(v.get("time")) for v in poly.iter("Vertex")]
        assert times == sorted(times) and len(times) >= 2
    stop = root.find(".//StopTrigger//SimulationTimeCondition")
    assert float(stop.get("value")) == pytest.approx(finding.misbehavior.time + 2.0)
    # the road is netconvert's OpenDRIVE in the trace's (SUMO's) coordinates: the same bounds as the network's
    header = ET.parse(tmp_path / f"{finding.path.name}.xodr").getroot().find("header")
    west, south, east, north = (float(v) for v in next(ET.parse(TOWN).getroot().iter("location")).get(
        "convBoundary").split(","))
    assert [float(header.get(k)) for k in ("west", "south", "east", "north")] == [west, south, east, north]


def test_a_broken_file_fails_the_schema(finding, tmp_path):
    CliRunner().invoke(main, ["export", str(finding.path), "-o", str(tmp_path)])
    xosc = tmp_path / f"{finding.path.name}.xosc"
    xosc.write_text(xosc.read_text().replace("<Storyboard>", "<Storyboard><Nonsense/>", 1))
    with pytest.raises(xmlschema.XMLSchemaValidationError):
        validate_openscenario(xosc)


def test_not_a_finding_is_an_input_error(tmp_path):
    result = CliRunner().invoke(main, ["export", str(tmp_path)])
    assert result.exit_code == 2 and "no verdict.json" in result.output
