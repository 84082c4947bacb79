"""Every registered oracle keeps the plugin contract of :mod:`drivefuzz.oracle`.

The oracles are loaded through the entry points (as the CLI loads them), default-configured,
and run together through one real execution of a normal mission.
"""

from __future__ import annotations

import json
from collections.abc import Sequence
from pathlib import Path

import pytest
from pydantic import BaseModel

from drivefuzz.errors import InvalidConfig
from drivefuzz.sim.execute import execute
from drivefuzz.oracle import (
    Misbehavior,
    Oracle,
    OracleSettings,
    Termination,
    available_oracles,
    make_config,
    parse_oracle_options,
)
from drivefuzz.scenario import AdsSpec, Mission, Scenario, SimOptions

NET = str(Path(__file__).resolve().parent.parent / "networks" / "town.net.xml")
BUILTIN = {"collision", "lane_invasion", "speeding", "red_light", "immobility", "mission"}
ORACLES = available_oracles()


class Recording:
    """Wraps an oracle and keeps what each hook returned."""

    def __init__(self, oracle: Oracle):
        self.oracle = oracle
        self.frames: list[Sequence] = []
        self.ends: list[Sequence] = []

    def __getattr__(self, name):
        return getattr(self.oracle, name)

    def reset(self, ctx):
        self.oracle.reset(ctx)

    def on_frame(self, frame):
        out = self.oracle.on_frame(frame)
        self.frames.append(out)
        return out

    def on_end(self, trace, termination):
        out = self.oracle.on_end(trace, termination)
        self.ends.append(out)
        return out


@pytest.fixture(scope="module")
def faulty_run():
    """All oracles through one run full of misbehaviour (the executor goes on after each): rear-ended
    by a linear car, 1.5 x the speed limit, through the red light at B1, out of time before the goal."""
    from drivefuzz.scenario import Actor
    from ego.ads import ReferenceADS

    rammer = Actor(id="rammer", kind="vehicle", nav="linear", start_lane="B0B1_1", start_pos=5.0, speed=14.0,
                   dest_edge="B1C1")
    sc = Scenario(network=NET, mission=Mission(start_lane="B0B1_1", start_pos=30.0, goal_edge="B1C1", goal_pos=60.0),
                  sim=SimOptions(time_limit=15.0), ads=AdsSpec(name="ego"), actors=(rammer,))
    wrapped = {name: Recording(cls()) for name, cls in ORACLES.items()}
    ads = ReferenceADS({"fault": "no_traffic_lights", "speed_margin": 1.5})
    ex = execute(sc, ads=ads, oracles=list(wrapped.values()), stop_on_misbehavior=False)
    return ex, wrapped


@pytest.fixture(scope="module")
def normal_run():
    """All oracles, default-configured, through one normal mission (lane changes, turns, a red light)."""
    sc = Scenario(network=NET, mission=Mission(start_lane="A0B0_1", start_pos=10.0, goal_edge="B1C1", goal_pos=40.0),
                  sim=SimOptions(time_limit=90.0), ads=AdsSpec(name="ego"))
    wrapped = {name: Recording(cls()) for name, cls in ORACLES.items()}
    ex = execute(sc, oracles=list(wrapped.values()), stop_on_misbehavior=False)
    return ex, wrapped


def test_every_builtin_oracle_is_registered():
    assert BUILTIN <= set(ORACLES)


@pytest.mark.parametrize("name", sorted(ORACLES))
def test_class_contract(name):
    cls = ORACLES[name]
    assert issubclass(cls, Oracle)
    assert cls.name == name
    assert isinstance(cls.description, str) and cls.description.strip()
    assert "\n" not in cls.description.strip()
    assert issubclass(cls.Config, Oracle.Config) and issubclass(cls.Config, BaseModel)
    assert "enabled" in cls.Config.model_fields
    cfg = cls.Config()
    assert cfg.enabled is True
    # every setting has a default; those an oracle adds say what they mean (and their unit)
    for key, field in cls.Config.model_fields.items():
        assert not field.is_required(), f"{name}.{key} has no default"
        if key not in Oracle.Config.model_fields and field.annotation in (float, int):
            assert field.description and field.description.strip(), f"{name}.{key} has no description"
    # the config round-trips through JSON (campaign config files)
    assert cls.Config.model_validate(json.loads(cfg.model_dump_json())) == cfg
    assert cls.__doc__ and len(cls.__doc__.strip()) > 40


@pytest.mark.parametrize("name", sorted(ORACLES))
def test_unknown_or_invalid_config_is_rejected(name):
    cls = ORACLES[name]
    with pytest.raises(InvalidConfig) as err:
        cls({"no_such_setting": 1})
    assert "no_such_setting" in str(err.value) and name in str(err.value)
    with pytest.raises(InvalidConfig):
        make_config(cls, {"enabled": "not a bool"})
    with pytest.raises(InvalidConfig):
        parse_oracle_options([f"{name}.no_such_setting=1"]).instantiate()
    # every known setting can be set from the command line (to its default, which is valid)
    for key, field in cls.Config.model_fields.items():
        if key == "enabled":
            continue
        pairs = [f"{name}.{key}={json.dumps(field.default)}"]
        (o,) = [o for o in parse_oracle_options(pairs).instantiate() if o.name == name]
        assert getattr(o.config, key) == field.default
    # and switching the oracle off
    assert name not in {type(o).name for o in parse_oracle_options([], disabled=[name]).instantiate()}
    assert name in {type(o).name for o in parse_oracle_options([]).instantiate()}


def test_settings_instantiate_every_oracle():
    oracles = OracleSettings().instantiate()
    assert {o.name for o in oracles} == set(ORACLES)


@pytest.mark.parametrize("run", ["normal_run", "faulty_run"])
@pytest.mark.parametrize("name", sorted(ORACLES))
def test_hooks_return_sequences_of_misbehaviors(request, run, name):
    ex, wrapped = request.getfixturevalue(run)
    rec = wrapped[name]
    assert len(rec.frames) == ex.trace.n_frames
    assert len(rec.ends) == 1
    returned = []
    for out in rec.frames + rec.ends:
        assert isinstance(out, Sequence) and not isinstance(out, str)
        returned.extend(out)
    # everything returned, and nothing else, reached the execution's record
    assert returned == [m for m in ex.misbehaviors if m.oracle == name]
    for m in returned:
        assert isinstance(m, Misbehavior)
        assert m.oracle == name and isinstance(m.kind, str) and m.kind
        assert 0 <= m.frame < ex.trace.n_frames
        assert m.time == pytest.approx(float(ex.trace["t"][m.frame]), abs=1e-6)
        assert all(isinstance(a, str) for a in m.actors)
        assert Misbehavior.from_dict(json.loads(json.dumps(m.as_dict()))) == m


def test_faulty_run_exercises_the_records(faulty_run):
    """The record checks above are not vacuous: in the faulty run these oracles report."""
    ex, _ = faulty_run
    fired = {(m.oracle, m.kind) for m in ex.misbehaviors}
    assert {("collision", "vehicle"), ("speeding", "speeding"), ("red_light", "red"), ("mission", "timeout")} <= fired
    assert ex.termination is Termination.TIME_LIMIT


def test_normal_mission_has_no_misbehaviour(normal_run):
    ex, _ = normal_run
    assert ex.termination is Termination.GOAL_REACHED
    assert ex.misbehaviors == ()
