"""Export a finding to OpenSCENARIO 1.2 (``.xosc``) and OpenDRIVE (``.xodr``) for other simulators.

- The road: netconvert's OpenDRIVE output of the finding's network (``--opendrive-output``), which keeps
  SUMO's Cartesian coordinates, so the trace's positions are world positions in it.
- The scenario (built with scenariogeneration): the ego and every actor as entities at their first traced
  pose, each following its traced trajectory (a polyline of timed world positions every
  :data:`SAMPLE_S` seconds, absolute timing), the weather (fog as visual range from the sensors' range
  model, rain as precipitation, the sun), and a stop trigger :data:`TAIL_S` after the failure.

The ego's trajectory is what the ADS under test drove: the exported file replays the failure, for a
simulator or a viewer, rather than testing another ADS. Units: metres, seconds, radians.
"""

from __future__ import annotations

import math
import subprocess
from pathlib import Path

import numpy as np

import drivefuzz
from drivefuzz.errors import SimulationError
from drivefuzz.scenario import Scenario

#: [s] between the exported trajectory vertices
SAMPLE_S = 0.5
#: [s] simulated after the failure before the exported scenario stops
TAIL_S = 2.0
#: OpenSCENARIO minor version written (1.2 is what most simulators read)
OSC_MINOR = 2


def schema_path() -> Path:
    """The OpenSCENARIO 1.2 XSD shipped with scenariogeneration."""
    import scenariogeneration

    return Path(scenariogeneration.__file__).resolve().parent.parent / "schemas" / f"OpenSCENARIO_1_{OSC_MINOR}.xsd"


def write_opendrive(net: Path, out: Path) -> Path:
    """netconvert the SUMO network into OpenDRIVE."""
    proc = subprocess.run([drivefuzz.sumo_binary("netconvert"), "--sumo-net-file", str(net),
                           "--opendrive-output", str(out), "--no-warnings"], capture_output=True, text=True, timeout=600)
    if proc.returncode != 0:
        raise SimulationError(f"netconvert could not write OpenDRIVE for {net}: {proc.stderr.strip()[-300:]}")
    return out


def export_openscenario(scenario: Scenario, trace, failure_time: float, out_dir: Path, name: str) -> tuple[Path, Path]:
    """Write ``<name>.xodr`` and ``<name>.xosc`` into ``out_dir``; return both paths."""
    from scenariogeneration import xosc

    out_dir.mkdir(parents=True, exist_ok=True)
    xodr = write_opendrive(scenario.network_path(), out_dir / f"{name}.xodr")
    entities, init = xosc.Entities(), xosc.Init()
    storyboard = xosc.StoryBoard(init, _stop_at(xosc, failure_time + TAIL_S))
    init.add_global_action(xosc.EnvironmentAction(_environment(xosc, scenario)))
    params = trace.meta
    tracks = [("ego", "vehicle", float(params.get("ego_length", 4.6)), float(params.get("ego_width", 1.9)),
               trace["t"], trace["x"], trace["y"], trace["heading"])]
    a = trace.actors
    for j, aid in enumerate(a.ids):
        rows = np.flatnonzero(a.actor == j)
        if len(rows):
            t = trace["t"][a.frame[rows]]
            tracks.append((aid, a.kinds[j], float(a.length[j]), float(a.width[j]), t, a.x[rows], a.y[rows],
                           a.heading[rows]))
    for aid, kind, length, width, t, x, y, h in tracks:
        entities.add_scenario_object(aid, _entity(xosc, aid, kind, length, width))
        init.add_init_action(aid, xosc.TeleportAction(xosc.WorldPosition(float(x[0]), float(y[0]), 0.0, float(h[0]))))
        keep = _sample(np.asarray(t, dtype=float))
        if len(keep) < 2:
            continue
        poly = xosc.Polyline([float(t[k]) for k in keep],
                             [xosc.WorldPosition(float(x[k]), float(y[k]), 0.0, float(h[k])) for k in keep])
        trajectory = xosc.Trajectory(f"{aid}_trace", False).add_shape(poly)
        follow = xosc.FollowTrajectoryAction(trajectory, xosc.FollowingMode.position,
                                             xosc.ReferenceContext.absolute, 1, 0)
        event = xosc.Event(f"{aid}_follows", xosc.Priority.override)
        event.add_action(f"{aid}_trajectory", follow)
        event.add_trigger(_at_time(xosc, 0.0))
        maneuver = xosc.Maneuver(f"{aid}_maneuver").add_event(event)
        storyboard.add_maneuver(maneuver, aid)
    sc = xosc.Scenario(f"drivefuzz {name}", "drivefuzz", xosc.ParameterDeclarations(), entities, storyboard,
                       xosc.RoadNetwork(roadfile=xodr.name), xosc.Catalog(), osc_minor_version=OSC_MINOR)
    xosc_path = out_dir / f"{name}.xosc"
    sc.write_xml(str(xosc_path))
    return xosc_path, xodr


def validate_openscenario(path: Path) -> None:
    """Raise ``xmlschema.XMLSchemaValidationError`` when ``path`` is not valid OpenSCENARIO."""
    import xmlschema

    xmlschema.XMLSchema(str(schema_path())).validate(str(path))


def _sample(t: np.ndarray) -> list[int]:
    """Indices of ``t`` every :data:`SAMPLE_S` seconds, the last one included, strictly increasing in time."""
    keep, last = [], -math.inf
    for k, tk in enumerate(t):
        if tk - last >= SAMPLE_S - 1e-9:
            keep.append(k)
            last = tk
    if keep and keep[-1] != len(t) - 1 and t[-1] > t[keep[-1]]:
        keep.append(len(t) - 1)
    return keep


def _entity(xosc, name: str, kind: str, length: float, width: float):
    if kind == "pedestrian":
        return xosc.Pedestrian(name, 80.0, xosc.PedestrianCategory.pedestrian,
                               xosc.BoundingBox(width, length, 1.8, 0.0, 0.0, 0.9))
    box = xosc.BoundingBox(width, length, 1.5, 0.0, 0.0, 0.75)
    front = xosc.Axle(0.5, 0.65, 1.6, 1.4, 0.33)
    rear = xosc.Axle(0.0, 0.65, 1.6, -1.4, 0.33)
    return xosc.Vehicle(name, xosc.VehicleCategory.car, box, front, rear, 69.0, 10.0, 10.0)


def _environment(xosc, sc: Scenario):
    """Fog as a visual range (as the reference ADS's sensing has it: 100 m in clear air, 15 m at fog 100),
    rain as precipitation, the sun as given."""
    w = sc.weather
    visual = int(round(100.0 * (1.0 - 0.85 * w.fog / 100.0)))
    rain = w.rain / 100.0
    weather = xosc.Weather(fog=xosc.Fog(visual),
                           precipitation=xosc.Precipitation(xosc.PrecipitationType.rain if rain > 0
                                                            else xosc.PrecipitationType.dry, rain),
                           sun=xosc.Sun(1000.0, math.radians(w.sun_azimuth_deg), math.radians(w.sun_altitude_deg)))
    return xosc.Environment("drivefuzz", xosc.TimeOfDay(False, 2026, 1, 1, 12, 0, 0), weather,
                            xosc.RoadCondition(1.0))


def _at_time(xosc, t: float):
    return xosc.ValueTrigger(f"at_{t:g}_s", 0, xosc.ConditionEdge.none,
                             xosc.SimulationTimeCondition(t, xosc.Rule.greaterOrEqual))


def _stop_at(xosc, t: float):
    return xosc.ValueTrigger("stop", 0, xosc.ConditionEdge.rising, xosc.SimulationTimeCondition(t, xosc.Rule.greaterThan),
                             "stop")
