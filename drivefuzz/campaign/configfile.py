"""The ``--config`` file of ``drivefuzz fuzz`` and ``drivefuzz run``, validated at load.

A TOML (or JSON) file with the sections ``[fuzz]``, ``[ads]``, ``[oracles.NAME]``,
``[mutation]`` and ``[quality]``. Every mistake (an unknown section or key, a
value of the wrong type, a number out of range, a nesting too deep to parse) is
one :class:`~drivefuzz.errors.InvalidConfig` naming the file, the field and what
would be valid. What comes out is plain data that :mod:`drivefuzz.cli` merges
with the command line (which wins).
"""

from __future__ import annotations

import json
import tomllib
from pathlib import Path
from typing import Any, Literal

from pydantic import BaseModel, ConfigDict, Field, ValidationError, field_validator

from drivefuzz.errors import InvalidConfig
from drivefuzz.scenario.model import OptionValue

STRATEGIES = ("all", "congestion", "entropy", "instability", "maneuver", "mix")
#: [s] the longest wall-clock limit of one execution that makes sense (a day)
MAX_EXEC_TIMEOUT_S = 86400.0


class _Section(BaseModel):
    model_config = ConfigDict(extra="forbid", strict=True, allow_inf_nan=False)


class FuzzSection(_Section):
    """``[fuzz]``: the defaults of ``drivefuzz fuzz``'s options (None: not set here)."""

    cycles: int | None = Field(default=None, ge=1)
    population: int | None = Field(default=None, ge=1)
    strategy: Literal[STRATEGIES] | None = None  # type: ignore[valid-type]
    seed: int | None = Field(default=None, ge=0)
    budget: str | float | None = None  # e.g. "10m"; read by parse_duration
    max_execs: int | None = Field(default=None, ge=1)
    feedback: Literal["risk", "paper", "random"] | None = None
    no_feedback: bool = False
    single_pass: bool = False
    patience: int | None = Field(default=None, ge=1)
    continue_after_finding: bool = False
    shrink: int | None = Field(default=None, ge=0, le=1000, description="executions to shrink a new finding")
    time_limit: float | None = Field(default=None, gt=0.0, le=MAX_EXEC_TIMEOUT_S, description="[s] simulated")
    no_isolation: bool = False
    exec_timeout: float | None = Field(default=None, gt=0.0, le=MAX_EXEC_TIMEOUT_S, description="[s] wall clock")


class AdsSection(_Section):
    name: str | None = Field(default=None, min_length=1)
    options: dict[str, OptionValue] = Field(default_factory=dict)


class ConfigFile(_Section):
    fuzz: FuzzSection = Field(default_factory=FuzzSection)
    ads: AdsSection = Field(default_factory=AdsSection)
    oracles: dict[str, dict[str, Any]] = Field(default_factory=dict)
    mutation: dict[str, Any] = Field(default_factory=dict)
    quality: dict[str, Any] = Field(default_factory=dict)


def read_data_file(path: Path, what: str = "TOML or JSON") -> Any:
    """Parse a TOML (or, by its suffix, JSON) file; any failure is one InvalidConfig naming it."""
    try:
        text = path.read_text()
        return json.loads(text) if path.suffix == ".json" else tomllib.loads(text)
    except (ValueError, UnicodeDecodeError) as exc:  # JSONDecodeError and TOMLDecodeError are ValueErrors
        raise InvalidConfig(str(path), None, f"cannot parse ({' '.join(str(exc).split())})", f"valid {what}") from None
    except RecursionError:
        raise InvalidConfig(str(path), None, "cannot parse (nested too deeply)", f"valid {what}") from None
    except OSError as exc:
        raise InvalidConfig(str(path), None, f"cannot read ({exc.strerror})", f"a readable {what} file") from None


def pydantic_error(source: str, exc: ValidationError, model: type[BaseModel], prefix: str = "") -> InvalidConfig:
    """The first error of ``exc`` as one InvalidConfig naming ``source`` and the field."""
    err = exc.errors()[0]
    loc = [str(p) for p in err["loc"]]
    field = ".".join(([prefix] if prefix else []) + loc) or None
    if err["type"] == "extra_forbidden":
        owner = model
        for part in loc[:-1]:
            sub = owner.model_fields.get(part)
            ann = getattr(sub, "annotation", None) if sub else None
            if not (isinstance(ann, type) and issubclass(ann, BaseModel)):
                owner = None
                break
            owner = ann
        if owner is not None:
            what = "unknown section" if owner is ConfigFile else "unknown key"
            return InvalidConfig(source, field, what, ", ".join(owner.model_fields))
        return InvalidConfig(source, field, "unknown key")
    return InvalidConfig(source, field, err["msg"])


def load_config_file(path: str | None) -> dict[str, Any]:
    """The validated ``--config`` file as plain data (``{}`` without one); unset keys are left out."""
    if not path:
        return {}
    p = Path(path)
    if not p.is_file():
        raise InvalidConfig(path, None, "no such config file", "a TOML or JSON file")
    data = read_data_file(p)
    if not isinstance(data, dict):
        raise InvalidConfig(path, None, f"is a JSON {type(data).__name__}, not a table of sections",
                            "sections " + ", ".join(ConfigFile.model_fields))
    try:
        cfg = ConfigFile.model_validate(data)
    except ValidationError as exc:
        raise pydantic_error(path, exc, ConfigFile) from None
    from drivefuzz.search.mutate import MutationConfig
    from drivefuzz.search.quality import QualityConfig

    for name, model in (("mutation", MutationConfig), ("quality", QualityConfig)):
        try:
            model.model_validate(getattr(cfg, name))
        except ValidationError as exc:
            raise pydantic_error(path, exc, model, prefix=name) from None
    out = cfg.model_dump(exclude_none=True)
    if cfg.fuzz.budget is not None:
        from drivefuzz.campaign.fuzz import parse_duration

        parse_duration(cfg.fuzz.budget, source=f"{path}: fuzz.budget")
    return out


class ManifestConfig(BaseModel):
    """The ``config`` of a campaign's manifest.json: the types a seed job relies on (more keys may follow)."""

    model_config = ConfigDict(extra="allow", strict=True, allow_inf_nan=False)
    cycles: int = Field(ge=1)
    population: int = Field(ge=1)
    strategy: Literal[STRATEGIES]  # type: ignore[valid-type]
    seed: int = Field(ge=0)
    budget_s: float | None = Field(default=None, gt=0.0)
    max_execs: int | None = Field(default=None, ge=1)
    feedback: bool | Literal["risk", "paper", "random"] = "risk"
    continue_after_finding: bool = False
    reproduce_incidents: bool = True  # manifests from before the key: their campaigns reproduced incidents
    shrink: int = Field(default=0, ge=0)
    ads: AdsSection = Field(default_factory=AdsSection)
    oracles: dict[str, dict[str, Any]] = Field(default_factory=dict)
    mutation: dict[str, Any] = Field(default_factory=dict)
    quality: dict[str, Any] = Field(default_factory=dict)
    time_limit: float | None = Field(default=None, gt=0.0, le=MAX_EXEC_TIMEOUT_S)
    isolate: bool = True
    exec_timeout_s: float = Field(default=300.0, gt=0.0, le=MAX_EXEC_TIMEOUT_S)


class ManifestFile(BaseModel):
    """A campaign's manifest.json, as far as ``--resume`` reads it."""

    model_config = ConfigDict(extra="allow", strict=True)
    config: ManifestConfig
    seeds: list[str] = Field(min_length=1)
    command: list[str] = Field(default_factory=list)

    @field_validator("seeds")
    @classmethod
    def _inside(cls, seeds: list[str]) -> list[str]:
        for s in seeds:
            if Path(s).is_absolute() or ".." in Path(s).parts:
                raise ValueError(f"seed folder {s!r} is not inside the campaign folder")
        return seeds
