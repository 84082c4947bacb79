"""A newcomer's run (issue 15): seeds found next to the network, an ADS in the current folder, the analysis
extra, the plain progress lines, the simulated-time column, fuzzing a network netgenerate made."""

from __future__ import annotations

import re
import shutil

import pytest
from click.testing import CliRunner

from drivefuzz.cli import main
from drivefuzz.errors import InvalidConfig

from conftest import ROOT, TOWN


def _no_generation(*_args, **_kwargs):
    raise AssertionError("seeds were generated: the network's own seeds were not found")


def test_seeds_are_found_next_to_the_network_from_any_folder(tmp_path, monkeypatch):
    """networks/town.net.xml -> seeds/town/, whatever the current folder; nothing is written there."""
    from drivefuzz import cli
    from drivefuzz.scenario.seed import list_seeds
    from drivefuzz.scenario.sumofiles import load_scenario

    monkeypatch.chdir(tmp_path)
    monkeypatch.setattr("drivefuzz.scenario.seed.generate_seeds", _no_generation)
    seeds = cli._seeds_for(str(TOWN), None)
    own = [load_scenario(p) for p in list_seeds(ROOT / "seeds" / "town")]
    assert [s.content_hash() for s in seeds] == [s.content_hash() for s in own]
    assert list(tmp_path.iterdir()) == []


def test_a_campaign_file_names_its_seed_folder(tmp_path, monkeypatch):
    """[campaign] seeds = "mine": mine/<net>/ is used before the network's own seeds."""
    from drivefuzz import cli
    from drivefuzz.campaign.batch import load_campaign_file
    from drivefuzz.scenario.sumofiles import load_scenario

    mine = tmp_path / "mine" / "town"
    mine.mkdir(parents=True)
    shutil.copytree(ROOT / "seeds" / "town" / "003", mine / "000")
    manifest = mine / "000" / "scenario.json"
    manifest.write_text(re.sub(r'"network": "[^"]*"', f'"network": "{TOWN}"', manifest.read_text()))
    spec_file = tmp_path / "c.toml"
    spec_file.write_text(f'[campaign]\nseeds = "mine"\n[matrix]\nnetworks = ["{TOWN}"]\n')
    spec = load_campaign_file(spec_file)
    assert spec.seeds_root == (tmp_path / "mine").resolve()
    monkeypatch.setattr("drivefuzz.scenario.seed.generate_seeds", _no_generation)
    seeds = cli._seeds_for(str(TOWN), None, 8, spec.seeds_root)
    assert [s.content_hash() for s in seeds] == [load_scenario(mine / "000").content_hash()]
    spec_file.write_text(f'[campaign]\nseeds = "nowhere"\n[matrix]\nnetworks = ["{TOWN}"]\n')
    with pytest.raises(InvalidConfig, match="campaign.seeds"):
        load_campaign_file(spec_file)
