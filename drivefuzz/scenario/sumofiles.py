"""Scenario <-> SUMO files, losslessly.

A scenario folder holds what ``sumo``/``sumo-gui`` load as they are::

    scenario.json     manifest: network, ADS, seed, simulation options (what SUMO has no element for)
    routes.rou.xml    the ego (id "ego") and every actor, sorted by depart time
    fuzz.add.xml      puddles as polygons (+ friction steps on the lanes under them), weather as a POI,
                      shifted traffic-light programs as ``<tlLogic programID="drivefuzz-shift">``
    scenario.sumocfg  ties them together: ``sumo-gui -c scenario.sumocfg``

Behaviour SUMO's XML cannot express (navigation type, maneuver schedule,
jaywalking target, exact model values) travels in ``<param key="drivefuzz.*">``.
Floats are written with ``repr`` so that reading gives back the same numbers.
Additional files carry no schema header and must be loaded with ``-X never``:
``friction`` on a ``<step>`` is not in SUMO's XSD.
"""

from __future__ import annotations

import hashlib
import json
import math
import os
import shutil
import xml.etree.ElementTree as ET
from pathlib import Path
from typing import Any

from pydantic import ValidationError

from drivefuzz.errors import InvalidScenario
from drivefuzz.scenario.signals import PROGRAM_ID, shiftable, tl_logic_element
from drivefuzz.scenario.model import (
    EGO_LENGTH,
    EGO_WIDTH,
    SCHEMA_VERSION,
    Actor,
    ActorKind,
    AdsSpec,
    Maneuver,
    Mission,
    NavType,
    Puddle,
    Scenario,
    SignalShift,
    SimOptions,
    Weather,
    lane_index,
)
from drivefuzz.storage import atomic_write_text

MANIFEST = "scenario.json"
ROUTES = "routes.rou.xml"
ADDITIONAL = "fuzz.add.xml"
SUMOCFG = "scenario.sumocfg"
#: [s] how long a lane change of SUMO's own drivers takes (SUMO's continuous lane-change model): without it a
#: car jumps 3.5 m sideways in one step. A maneuver's lane change takes its own duration (sim/world.py).
LANE_CHANGE_DURATION = 3.0

EGO_ID = "ego"
EGO_TYPE = "drivefuzz_ego"
#: vType per (kind, navigation type); attributes from the SUMO notes (lawful, reckless, walker).
VTYPES: dict[str, dict[str, str]] = {
    EGO_TYPE: {"vClass": "passenger", "color": "1,0,0", "speedFactor": "1", "speedDev": "0", "sigma": "0"},
    "drivefuzz_lawful": {"vClass": "passenger", "color": "0.8,0.8,0.8", "sigma": "0", "speedFactor": "1",
                         "speedDev": "0", "impatience": "0"},
    "drivefuzz_maneuver": {"vClass": "passenger", "color": "1,0.6,0", "sigma": "0", "speedFactor": "1",
                           "speedDev": "0", "impatience": "0"},
    "drivefuzz_linear": {"vClass": "passenger", "color": "1,0,1", "sigma": "0", "speedFactor": "1.3",
                         "speedDev": "0", "minGap": "0.5", "tau": "0.5", "jmDriveAfterRedTime": "3600",
                         "jmDriveRedSpeed": "20", "jmIgnoreFoeProb": "1", "jmIgnoreFoeSpeed": "50",
                         "jmIgnoreJunctionFoeProb": "1", "jmTimegapMinor": "0", "lcAssertive": "10",
                         "lcCooperative": "0"},
    "drivefuzz_immobile": {"vClass": "passenger", "color": "0.4,0.4,0.4", "sigma": "0"},
    "drivefuzz_walker": {"vClass": "pedestrian", "color": "0,0.6,0", "speedDev": "0"},
    "drivefuzz_walker_linear": {"vClass": "pedestrian", "color": "1,0,1", "speedDev": "0",
                                "jmDriveAfterRedTime": "3600", "jmIgnoreFoeProb": "1", "jmIgnoreFoeSpeed": "50"},
}


def actor_vtype(actor: Actor) -> str:
    if actor.kind is ActorKind.PEDESTRIAN:
        return "drivefuzz_walker_linear" if actor.nav is NavType.LINEAR else "drivefuzz_walker"
    return {
        NavType.AUTOPILOT: "drivefuzz_lawful",
        NavType.MANEUVER: "drivefuzz_maneuver",
        NavType.LINEAR: "drivefuzz_linear",
        NavType.IMMOBILE: "drivefuzz_immobile",
    }[actor.nav]


def _f(x: float) -> str:
    return repr(float(x))


def _param(parent: ET.Element, key: str, value: Any) -> None:
    ET.SubElement(parent, "param", key=key, value=str(value))


def _params(elem: ET.Element) -> dict[str, str]:
    return {p.get("key"): p.get("value") for p in elem.findall("param")}


# ---------------------------------------------------------------- writing
def routes_xml(scenario: Scenario, route_edges: tuple[str, ...]) -> str:
    """The route file (the ego's vType has the size of the physics' car, :data:`EGO_LENGTH` x :data:`EGO_WIDTH`)."""
    root = ET.Element("routes")
    for vid, attrs in VTYPES.items():
        vt = ET.SubElement(root, "vType", id=vid, **attrs)
        if vid == EGO_TYPE:
            vt.set("length", _f(EGO_LENGTH))
            vt.set("width", _f(EGO_WIDTH))
            vt.set("minGap", "1.0")
    m = scenario.mission
    ego_el = ET.Element("vehicle", id=EGO_ID, type=EGO_TYPE, depart="0.00",
                        departLane=str(lane_index(m.start_lane)), departPos=_f(m.start_pos),
                        departSpeed=_f(m.start_speed), arrivalPos=_f(m.goal_pos))
    ET.SubElement(ego_el, "route", edges=" ".join(route_edges))
    _param(ego_el, "drivefuzz.role", "ego")
    entries: list[tuple[float, int, ET.Element]] = [(0.0, -1, ego_el)]
    for order, actor in enumerate(scenario.actors):
        el = _actor_element(actor)
        _param(el, "drivefuzz.order", order)  # the scenario's order; the file is sorted by depart
        entries.append((actor.depart, order, el))
    # SUMO drops route entries that are out of depart order: sort (stable, ego first at t=0).
    entries.sort(key=lambda e: (e[0], e[1]))
    for _, _, el in entries:
        root.append(el)
    ET.indent(root)
    return ET.tostring(root, encoding="unicode") + "\n"


def _actor_element(a: Actor) -> ET.Element:
    vtype = actor_vtype(a)
    depart = _f(a.depart)
    if a.kind is ActorKind.VEHICLE:
        dest = a.dest_edge or a.start_edge
        el = ET.Element("trip", id=a.id, type=vtype, depart=depart, departLane=str(lane_index(a.start_lane)),
                        departPos=_f(a.start_pos), departSpeed="0" if a.nav is NavType.IMMOBILE else "max",
                        to=dest, **{"from": a.start_edge})
        if a.dest_pos is not None:
            el.set("arrivalPos", _f(a.dest_pos))
        if a.nav is NavType.IMMOBILE:
            ET.SubElement(el, "stop", lane=a.start_lane, endPos=_f(a.start_pos), duration="1000000")
    else:
        el = ET.Element("person", id=a.id, type=vtype, depart=depart, departPos=_f(a.start_pos))
        if a.nav is NavType.IMMOBILE or (a.nav is NavType.LINEAR and a.dest_edge is None):
            ET.SubElement(el, "stop", lane=a.start_lane, endPos=_f(a.start_pos), duration="1000000")
        else:
            walk = ET.SubElement(el, "walk", to=a.dest_edge or a.start_edge, **{"from": a.start_edge})
            if a.dest_pos is not None:
                walk.set("arrivalPos", _f(a.dest_pos))
    _param(el, "drivefuzz.nav", a.nav.value)
    _param(el, "drivefuzz.start_lane", a.start_lane)
    _param(el, "drivefuzz.speed", _f(a.speed))
    if a.dest_edge is not None:
        _param(el, "drivefuzz.dest_edge", a.dest_edge)
    if a.dest_pos is not None:
        _param(el, "drivefuzz.dest_pos", _f(a.dest_pos))
    if a.dest_xy is not None:
        _param(el, "drivefuzz.dest_xy", f"{_f(a.dest_xy[0])},{_f(a.dest_xy[1])}")
    if a.maneuvers:
        _param(el, "drivefuzz.maneuvers", json.dumps([m.model_dump(mode="json") for m in a.maneuvers]))
    return el


def additional_xml(scenario: Scenario, puddle_lanes: list[list[str]], weather_xy: tuple[float, float],
                   net_path: str) -> str:
    root = ET.Element("additional")
    for sig in scenario.signals:  # validate() checked that each program can be shifted
        tl = tl_logic_element(sig.tls, shiftable(net_path, sig.tls), sig.shift)
        _param(tl, "drivefuzz.shift", _f(sig.shift))
        root.append(tl)
    for i, p in enumerate(scenario.puddles):
        shape = " ".join(f"{x:.3f},{y:.3f}" for x, y in p.corners())
        poly = ET.SubElement(root, "poly", id=f"puddle_{i}", type="drivefuzz.puddle", color="0,90,200,160",
                             fill="1", layer=PUDDLE_LAYER, shape=shape)
        for key in ("x", "y", "length", "width", "rotation", "friction"):
            _param(poly, f"drivefuzz.{key}", _f(getattr(p, key)))
    for i, p in enumerate(scenario.puddles):
        lanes = puddle_lanes[i] if i < len(puddle_lanes) else []
        if lanes:
            vss = ET.SubElement(root, "variableSpeedSign", id=f"puddle_{i}_friction", lanes=" ".join(lanes))
            ET.SubElement(vss, "step", time="0", friction=_f(p.friction))
    poi = ET.SubElement(root, "poi", id="drivefuzz.weather", type="drivefuzz.weather", color="0,0,0",
                        x=f"{weather_xy[0]:.3f}", y=f"{weather_xy[1]:.3f}", layer="2")
    for key, value in scenario.weather.model_dump().items():
        _param(poi, f"drivefuzz.{key}", _f(value))
    ET.indent(root)
    return ET.tostring(root, encoding="unicode") + "\n"


#: sumo-gui draws shapes by layer; the network is drawn at 0 and its lanes must not hide the puddles
PUDDLE_LAYER = "10"

#: the first lines of every scenario.sumocfg: what sumo-gui shows of it, and what it does not
SUMOCFG_NOTE = (
    "<!-- drivefuzz scenario. In a run, drivefuzz drives the ego (its ADS and vehicle physics) and moves the\n"
    "     scripted actors (linear, maneuver, immobile); sumo-gui -c on this file lets SUMO's own models drive\n"
    "     them instead, so what it shows is not the finding. To watch the finding, give drivefuzz replay this\n"
    "     folder and its gui flag (an XML comment cannot hold two dashes; see drivefuzz replay -h). -->\n"
)


def sumocfg_xml(net_rel: str, step_length: float, time_limit: float) -> str:
    return (
        SUMOCFG_NOTE + "<configuration>\n"
        f'    <input><net-file value="{net_rel}"/><route-files value="{ROUTES}"/>'
        f'<additional-files value="{ADDITIONAL}"/></input>\n'
        f'    <time><begin value="0"/><end value="{time_limit!r}"/><step-length value="{step_length!r}"/></time>\n'
        '    <processing><time-to-teleport value="-1"/><collision.action value="warn"/>'
        '<collision.check-junctions value="true"/>'
        f'<lanechange.duration value="{LANE_CHANGE_DURATION!r}"/></processing>\n'
        '    <random_number><seed value="0"/></random_number>\n'
        "</configuration>\n"
    )


def write_scenario(scenario: Scenario, folder: str | os.PathLike, *, base: str | os.PathLike | None = None,
                   durable: bool = True, portable: bool = False) -> Path:
    """Validate ``scenario`` against its network and write its folder. Returns the manifest path.

    ``base`` resolves a relative ``scenario.network`` (default: the current directory).
    The manifest refers to the network by a path relative to ``folder`` when it can.
    ``portable=True`` puts the network into the folder (a hard link where the filesystem allows, else a
    copy) and records its SHA-256, so that the folder replays wherever it is copied (findings).
    ``durable=False`` skips the atomic, fsync'd writes, for a scratch folder that
    is deleted after the run (the executor's; about 4 ms per execution).
    """
    from drivefuzz.scenario.roadmap import load_roadmap
    from drivefuzz.scenario.validate import puddle_lanes, validate

    folder = Path(folder)
    folder.mkdir(parents=True, exist_ok=True)
    net_path = scenario.network_path(base).resolve()
    rmap = load_roadmap(net_path)
    route = validate(scenario, rmap, source=str(folder / MANIFEST))
    net_hash = None
    if portable:
        net_ref, net_hash = _bring_network(net_path, folder), network_sha256(net_path)
    else:
        try:
            net_ref = os.path.relpath(net_path, folder.resolve())
        except ValueError:  # other drive on Windows
            net_ref = str(net_path)
    start = rmap.geom(scenario.mission.start_lane).position(scenario.mission.start_pos)
    write = atomic_write_text if durable else _plain_write
    write(folder / ROUTES, routes_xml(scenario, route))
    write(folder / ADDITIONAL,
                      additional_xml(scenario, [puddle_lanes(p, rmap) for p in scenario.puddles], start[:2],
                         str(net_path)))
    write(folder / SUMOCFG, sumocfg_xml(net_ref, scenario.sim.step_length, scenario.sim.time_limit))
    manifest = {
        "drivefuzz_scenario": SCHEMA_VERSION,
        "name": scenario.name,
        "network": net_ref,
        "routes": ROUTES,
        "additional": ADDITIONAL,
        "ads": scenario.ads.model_dump(mode="json"),
        "seed": scenario.seed,
        "sim": scenario.sim.model_dump(mode="json"),
    }
    if net_hash is not None:
        manifest["network_sha256"] = net_hash
    return write(folder / MANIFEST, json.dumps(manifest, indent=2, sort_keys=True) + "\n")


def network_sha256(path: str | os.PathLike) -> str:
    """SHA-256 of a network file's bytes (hex)."""
    digest = hashlib.sha256()
    with open(path, "rb") as fh:
        for block in iter(lambda: fh.read(1 << 20), b""):
            digest.update(block)
    return digest.hexdigest()


def _bring_network(net_path: Path, folder: Path) -> str:
    """Put the network file into ``folder`` under its own name; return that name."""
    target = folder / net_path.name
    if not target.exists():
        try:
            os.link(net_path, target)
        except OSError:  # another filesystem, or links not allowed
            shutil.copyfile(net_path, target)
    return net_path.name


def _plain_write(path: Path, text: str) -> Path:
    path.write_text(text, encoding="utf-8")
    return path


# ---------------------------------------------------------------- reading
def _pydantic_error(source: str, exc: ValidationError, prefix: str = "") -> InvalidScenario:
    err = exc.errors()[0]
    loc = ".".join(str(p) for p in err.get("loc", ()) if p != "__root__")
    field = f"{prefix}{'.' if prefix and loc else ''}{loc}" or None
    return InvalidScenario(source, field, err.get("msg", str(exc)))


def _parse_xml(path: Path) -> ET.Element:
    if not path.is_file():
        raise InvalidScenario(str(path), None, "file is missing", "a SUMO XML file written by drivefuzz")
    try:
        return ET.parse(path).getroot()
    except ET.ParseError as exc:
        raise InvalidScenario(str(path), None, f"malformed XML ({exc})") from None


def read_scenario(path: str | os.PathLike, *, validate_network: bool = True) -> Scenario:
    """Read a scenario folder (or its ``scenario.json``). The network path becomes absolute."""
    path = Path(path)
    manifest_path = path / MANIFEST if path.is_dir() else path
    folder = manifest_path.parent
    src = str(manifest_path)
    if not manifest_path.is_file():
        raise InvalidScenario(src, None, "no such scenario", "a folder holding scenario.json, or the file itself")
    try:
        manifest = json.loads(manifest_path.read_text())
    except (json.JSONDecodeError, UnicodeDecodeError) as exc:
        raise InvalidScenario(src, None, f"not valid JSON ({exc})") from None
    except RecursionError:
        raise InvalidScenario(src, None, "not valid JSON (nested too deeply)") from None
    if not isinstance(manifest, dict) or manifest.get("drivefuzz_scenario") != SCHEMA_VERSION:
        raise InvalidScenario(src, "drivefuzz_scenario", "missing or unsupported schema version",
                              f"{SCHEMA_VERSION}")
    for key in ("network", "routes", "additional"):
        if not isinstance(manifest.get(key), str):
            raise InvalidScenario(src, key, "missing", "a file name")
    routes_path = folder / manifest["routes"]
    add_path = folder / manifest["additional"]
    mission, actors = _read_routes(routes_path)
    puddles, weather, signals = _read_additional(add_path)
    net = Path(manifest["network"])
    net = net if net.is_absolute() else (folder / net).resolve()
    _check_network_hash(manifest, net, src)
    try:
        scenario = Scenario(
            network=str(net), mission=mission, actors=tuple(actors), puddles=tuple(puddles), weather=weather,
            signals=tuple(signals),
            ads=AdsSpec.model_validate(manifest.get("ads", {})), seed=manifest.get("seed", 0),
            sim=SimOptions.model_validate(manifest.get("sim", {})), name=manifest.get("name", folder.name),
        )
    except ValidationError as exc:
        raise _pydantic_error(src, exc) from None
    if validate_network:
        from drivefuzz.scenario.roadmap import load_roadmap
        from drivefuzz.scenario.validate import validate

        from drivefuzz.errors import InvalidNetwork

        try:
            rmap = load_roadmap(net)
        except InvalidNetwork as exc:
            raise InvalidScenario(src, "network", exc.problem, "path of a SUMO .net.xml relative to the folder") from None
        validate(scenario, rmap, source=src)
    return scenario


def _check_network_hash(manifest: dict, net: Path, src: str) -> None:
    """A portable folder's network must be the one it was made on (``network_sha256``)."""
    want = manifest.get("network_sha256")
    if want is None:
        return
    if not isinstance(want, str):
        raise InvalidScenario(src, "network_sha256", "not a string", "the hex SHA-256 of the network file")
    if not net.is_file():
        raise InvalidScenario(src, "network", f"no such network file {manifest['network']!r}",
                              "the network file next to scenario.json (copy the whole folder)")
    if network_sha256(net) != want:
        raise InvalidScenario(src, "network", f"{net.name} is not the network this scenario was made on "
                              f"(its SHA-256 differs from {want[:12]}...)", "the folder's own copy of the network")


def _read_routes(path: Path) -> tuple[Mission, list[Actor]]:
    root = _parse_xml(path)
    src = str(path)
    mission = None
    actors: list[tuple[int, Actor]] = []
    for el in root:
        if el.tag not in ("vehicle", "trip", "person"):
            continue
        params = _params(el)
        try:
            if params.get("drivefuzz.role") == "ego":
                edges = el.find("route").get("edges").split()
                mission = Mission(start_lane=f"{edges[0]}_{el.get('departLane')}", start_pos=float(el.get("departPos")),
                                  goal_edge=edges[-1], goal_pos=float(el.get("arrivalPos")),
                                  start_speed=float(el.get("departSpeed", 0)))
                continue
            dest_xy = params.get("drivefuzz.dest_xy")
            actors.append((int(params.get("drivefuzz.order", len(actors))), Actor(
                id=el.get("id"),
                kind=ActorKind.PEDESTRIAN if el.tag == "person" else ActorKind.VEHICLE,
                nav=NavType(params["drivefuzz.nav"]),
                start_lane=params["drivefuzz.start_lane"],
                start_pos=float(el.get("departPos")),
                speed=float(params["drivefuzz.speed"]),
                depart=float(el.get("depart")),
                dest_edge=params.get("drivefuzz.dest_edge"),
                dest_pos=float(params["drivefuzz.dest_pos"]) if "drivefuzz.dest_pos" in params else None,
                dest_xy=tuple(float(v) for v in dest_xy.split(",")) if dest_xy else None,
                maneuvers=tuple(Maneuver.model_validate(m) for m in json.loads(params.get("drivefuzz.maneuvers", "[]"))),
            )))
        except ValidationError as exc:
            raise _pydantic_error(src, exc, prefix=f"{el.tag}[{el.get('id')}]") from None
        except (KeyError, TypeError, AttributeError, ValueError, IndexError) as exc:
            raise InvalidScenario(src, f"{el.tag}[{el.get('id')}]",
                                  f"missing or malformed attribute or drivefuzz param ({type(exc).__name__}: {exc})",
                                  "what drivefuzz writes: a route of one or more edges, numbers, JSON maneuvers"
                                  ) from None
        except RecursionError:
            raise InvalidScenario(src, f"{el.tag}[{el.get('id')}]", "drivefuzz.maneuvers nested too deeply") from None
    if mission is None:
        raise InvalidScenario(src, "vehicle[ego]", "no ego vehicle",
                              'a <vehicle id="ego"> with <param key="drivefuzz.role" value="ego"/>')
    return mission, [a for _, a in sorted(actors, key=lambda p: p[0])]


def _read_additional(path: Path) -> tuple[list[Puddle], Weather, list[SignalShift]]:
    root = _parse_xml(path)
    src = str(path)
    puddles = []
    weather = Weather()
    signals = []
    for el in root:
        params = {k.removeprefix("drivefuzz."): v for k, v in _params(el).items()}
        try:
            if el.tag == "poly" and el.get("type") == "drivefuzz.puddle":
                puddles.append(Puddle(**{k: float(v) for k, v in params.items()}))
            elif el.tag == "poi" and el.get("type") == "drivefuzz.weather":
                weather = Weather(**{k: float(v) for k, v in params.items()})
            elif el.tag == "tlLogic" and el.get("programID") == PROGRAM_ID:
                signals.append(SignalShift(tls=el.get("id", ""), shift=float(params.get("shift", "nan"))))
        except ValidationError as exc:
            raise _pydantic_error(src, exc, prefix=f"{el.tag}[{el.get('id')}]") from None
        except ValueError as exc:
            raise InvalidScenario(src, f"{el.tag}[{el.get('id')}]", f"malformed param ({exc})") from None
    return puddles, weather, signals


def load_scenario(path: str | os.PathLike) -> Scenario:
    """Load a scenario from a folder, its ``scenario.json``, or a plain JSON dump of the model."""
    path = Path(path)
    if path.is_file() and path.name != MANIFEST and path.suffix == ".json":
        try:
            data = json.loads(path.read_text())
        except (json.JSONDecodeError, UnicodeDecodeError) as exc:
            raise InvalidScenario(str(path), None, f"not valid JSON ({exc})") from None
        except RecursionError:
            raise InvalidScenario(str(path), None, "not valid JSON (nested too deeply)") from None
        if not isinstance(data, dict):
            raise InvalidScenario(str(path), None, f"a JSON {type(data).__name__}, not a scenario object",
                                  "a scenario.json, or a JSON dump of a Scenario")
        if "drivefuzz_scenario" in data:
            return read_scenario(path)
        try:
            scenario = Scenario.model_validate(data)
        except ValidationError as exc:
            raise _pydantic_error(str(path), exc) from None
        net = scenario.network_path(path.parent)
        scenario = scenario.model_copy(update={"network": str(net.resolve())})
        from drivefuzz.scenario.roadmap import load_roadmap
        from drivefuzz.scenario.validate import validate

        validate(scenario, load_roadmap(net), source=str(path))
        return scenario
    return read_scenario(path)

