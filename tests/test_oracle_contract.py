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
from drivefuzz.execute import execute
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
    # every setting has a default and is documented by its type
    for key, field in cls.Config.model_fields.items():
        assert not field.is_required(), f"{name}.{key} has no default"
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
    # a known setting set from the command line, and switching the oracle off
    assert name not in {type(o).name for o in parse_oracle_options([], disabled=[name]).instantiate()}
    assert isinstance(cls(cls.Config()).config, cls.Config)


def test_settings_instantiate_every_oracle():
    oracles = OracleSettings().instantiate()
    assert {o.name for o in oracles} == set(ORACLES)


@pytest.mark.parametrize("name", sorted(ORACLES))
def test_hooks_return_sequences_of_misbehaviors(normal_run, name):
    ex, wrapped = normal_run
    rec = wrapped[name]
    assert len(rec.frames) == ex.trace.n_frames
    assert len(rec.ends) == 1
    for out in rec.frames + rec.ends:
        assert isinstance(out, Sequence) and not isinstance(out, str)
        for m in out:
            assert isinstance(m, Misbehavior)
            assert m.oracle == name and isinstance(m.kind, str)
            assert Misbehavior.from_dict(json.loads(json.dumps(m.as_dict()))) == m


def test_normal_mission_has_no_misbehaviour(normal_run):
    ex, _ = normal_run
    assert ex.termination is Termination.GOAL_REACHED
    assert ex.misbehaviors == ()
