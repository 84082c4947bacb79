"""`drivefuzz campaign`: the matrix file, a real run on a local Dask cluster, resume, and the Slurm example."""

from __future__ import annotations

import csv
import json
import re

import pytest
from click.testing import CliRunner

from drivefuzz.campaign.batch import cells, load_campaign_file
from drivefuzz.cli import main
from drivefuzz.errors import InvalidConfig

from conftest import ROOT, TOWN

pytestmark = pytest.mark.timeout(240)

SMALL = f"""
[campaign]
max_execs = 2
cycles = 1
population = 2
seeds_per_network = 1
time_limit = 30

[matrix]
networks = ["{TOWN}"]
strategies = ["all", "entropy"]
seeds = [0]
ads = [{{name = "ego", options = {{fault = "speeding"}}}}]

[run]
where = "local"
jobs = 2
"""


def test_small_campaign_runs_every_cell_and_resumes(tmp_path):
    spec_file = tmp_path / "c.toml"
    spec_file.write_text(SMALL)
    out = tmp_path / "out"
    result = CliRunner().invoke(main, ["campaign", str(spec_file), "-o", str(out)])
    assert result.exit_code == 1, result.output  # the faulty ADS is found speeding
    assert isinstance(result.exception, SystemExit), result.exception  # exit 1 by sys.exit, not a crash
    rows = list(csv.DictReader((out / "results.csv").open()))
    assert [r["cell"] for r in rows] == ["town all ego fault=speeding seed 0", "town entropy ego fault=speeding seed 0"]
    assert [r["folder"] for r in rows] == ["cells/town-all-ego-f1bffd-s0", "cells/town-entropy-ego-f1bffd-s0"]
    for r in rows:
        assert r["status"] == "done" and int(r["execs"]) >= 1 and int(r["findings"]) >= 1
        assert (out / r["folder"] / "index.sqlite").exists()
    assert any("speeding:" in r["by_oracle"] for r in rows)
    assert "town all ego fault=speeding seed 0" in (out / "results.md").read_text()
    page = (out / "results.html").read_text()  # the batch report: one self-contained page
    assert "town all ego fault=speeding seed 0" in page and "data:image/png;base64," in page
    assert not re.search(r"(src|href)=['\"](?!data:|#)", page)
    before = {p.name for r in rows for p in (out / r["folder"] / "findings").iterdir()}
    again = CliRunner().invoke(main, ["campaign", "--resume", str(out)])
    assert again.exit_code == 1, again.output
    after = {p.name for r in rows for p in (out / r["folder"] / "findings").iterdir()}
    assert after == before  # every cell was done: nothing re-run, nothing lost


@pytest.mark.parametrize("text, field", [
    ("[matrix]\nnetworks = []\n", "matrix.networks"),
    ("[matrix]\nnetworks = ['nowhere.net.xml']\n", "matrix.networks"),
    (f"[matrix]\nnetworks = ['{TOWN}']\nstrategies = ['chaos']\n", "matrix.strategies"),
    (f"[matrix]\nnetworks = ['{TOWN}']\n[run]\nwhere = 'moon'\n", "run.where"),
    (f"[matrix]\nnetworks = ['{TOWN}']\n[cluster]\ncores = 0\n", "cluster.cores"),
    (f"[matrix]\nnetworks = ['{TOWN}']\n[campaign]\nbudgett = '1m'\n", "campaign.budgett"),
    (f"[matrix]\nnetworks = ['{TOWN}']\n[campaign]\nbudget = 'soon'\n", "campaign.budget"),
    (f"[matrix]\nnetworks = ['{TOWN}']\nads = [{{name = 'nosuchads'}}]\n", "matrix.ads"),
    (f"[matrix]\nnetworks = ['{TOWN}']\nads = [{{name = 'ego', options = {{fault = 'bogus'}}}}]\n", "matrix.ads"),
    (f"[matrix]\nnetworks = ['{TOWN}']\nseeds = [0, 0]\n", "share the directory"),
])
def test_bad_campaign_file_is_one_line_naming_the_field(tmp_path, text, field):
    f = tmp_path / "bad.toml"
    f.write_text(text)
    with pytest.raises(InvalidConfig) as err:
        load_campaign_file(f)
    assert str(f) in str(err.value) and field in str(err.value)
    result = CliRunner().invoke(main, ["campaign", str(f), "-o", str(tmp_path / "o")])
    assert result.exit_code == 2 and len(result.output.strip().splitlines()) == 1 and field in result.output


def test_readme_slurm_example_makes_a_valid_job_script():
    from drivefuzz.campaign.cluster import make_batch_cluster

    example = ROOT / "examples" / "slurm-campaign.toml"
    assert example.read_text().strip() in (ROOT / "README.md").read_text()  # the README shows this very file
    spec = load_campaign_file(example)
    assert len(cells(spec)) == 24 and spec.run.where == "slurm"
    cluster = make_batch_cluster(spec.cluster.model_copy(update={"backend": spec.run.where}))
    try:
        script = cluster.job_script()
    finally:
        cluster.close()
    assert script.startswith("#!/usr/bin/env bash")
    for line in ("#SBATCH -p normal", "#SBATCH -A myproject", "#SBATCH -n 1", "#SBATCH --cpus-per-task=16",
                 "#SBATCH --mem=30G", "#SBATCH -t 04:00:00", "source ~/venvs/drivefuzz/bin/activate"):
        assert line in script, (line, script)
    worker = next(line for line in script.splitlines() if "distributed.cli.dask_worker" in line)
    assert "--nthreads 1" in worker and "--nworkers 16" in worker and "--nanny" in worker
    assert "--lifetime 13800s" in worker  # retire 10 minutes before the 4 h walltime


def test_campaign_json_records_the_resolved_matrix(tmp_path):
    spec_file = tmp_path / "c.toml"
    spec_file.write_text(SMALL.replace("max_execs = 2", "max_execs = 1").replace('"all", "entropy"', '"all"'))
    out = tmp_path / "out"
    CliRunner().invoke(main, ["campaign", str(spec_file), "-o", str(out)])
    saved = json.loads((out / "campaign.json").read_text())
    assert saved["matrix"]["networks"] == [str(TOWN.resolve())] and saved["campaign"]["max_execs"] == 1


def test_a_batch_system_that_is_not_installed_is_one_line(tmp_path):
    f = tmp_path / "c.toml"
    f.write_text(f"[matrix]\nnetworks = ['{TOWN}']\n[run]\nwhere = 'slurm'\n")
    result = CliRunner().invoke(main, ["campaign", str(f), "-o", str(tmp_path / "o")])
    assert result.exit_code == 2 and "sbatch" in result.output and len(result.output.strip().splitlines()) == 1
    assert not (tmp_path / "o").exists()  # nothing written: the fixed file can use the same directory


STARVING = (SMALL.replace("max_execs = 2", 'budget = "3s"').replace("time_limit = 30", "time_limit = 20")
            .replace(str(TOWN), str(ROOT / "networks" / "intersection.net.xml")).replace("jobs = 2", "jobs = 1")
            .replace('ads = [{name = "ego", options = {fault = "speeding"}}]\n', ""))


def test_a_cell_budget_counts_from_its_first_job_not_from_the_queue(tmp_path):
    """Two cells on one worker: the second cell's jobs wait for the first cell's; its 3 s start when they run
    (counted from submission, the second cell ran nothing). A cell that ran nothing is flagged and resumed."""
    import shutil

    spec_file = tmp_path / "c.toml"
    spec_file.write_text(STARVING)
    out = tmp_path / "out"
    result = CliRunner().invoke(main, ["campaign", str(spec_file), "-o", str(out)])
    assert result.exit_code in (0, 1), result.output
    rows = list(csv.DictReader((out / "results.csv").open()))
    assert len(rows) == 2 and all(int(r["execs"]) >= 1 for r in rows), rows
    assert "WARNING" not in result.output
    starved = out / rows[1]["folder"]  # as an earlier version left it: finished, with nothing run
    for sub in ("jobs", "corpus", "findings", "incidents", "budget"):
        shutil.rmtree(starved / sub, ignore_errors=True)
    (starved / "index.sqlite").unlink()
    (starved / "finished.json").write_text(json.dumps({"reason": "the time budget of 3s was spent", "executions": 0}))
    from drivefuzz.campaign.batch import results_table

    assert "WARNING: no executions" in results_table(out, load_campaign_file(spec_file))[1]["status"]
    again = CliRunner().invoke(main, ["campaign", "--resume", str(out)])
    assert again.exit_code in (0, 1), again.output
    rows = list(csv.DictReader((out / "results.csv").open()))
    assert int(rows[1]["execs"]) >= 1 and "WARNING" not in rows[1]["status"], rows


def _row(network, strategy, fault, seed, distinct):
    return {"network": network, "strategy": strategy, "ads": "ego", "ads_options": json.dumps({"fault": fault}),
            "seed": seed, "execs": 100, "distinct": distinct}


def test_cells_that_differ_only_in_the_seed_are_compared_with_mann_whitney_and_a12():
    from drivefuzz.campaign.compare import comparison_markdown, comparisons, configurations

    rows = ([_row("town.net.xml", "all", "speeding", s, d) for s, d in enumerate([5, 6, 7, 6, 8])]
            + [_row("town.net.xml", "entropy", "speeding", s, d) for s, d in enumerate([1, 2, 1, 0, 2])]
            + [_row("highway.net.xml", "all", "speeding", 0, 3)])
    configs = configurations(rows)
    assert [(c.label, c.distinct) for c in configs][:2] == [
        ('town.net.xml all ego {"fault": "speeding"}', (5.0, 6.0, 7.0, 6.0, 8.0)),
        ('town.net.xml entropy ego {"fault": "speeding"}', (1.0, 2.0, 1.0, 0.0, 2.0))]
    ((a, b, p, e),) = comparisons(configs)  # the highway has one repetition: not compared
    assert (a.strategy, b.strategy) == ("all", "entropy") and e == 1.0 and p < 0.05
    md = "\n".join(comparison_markdown(configs))
    assert "| 6.40 |" in md and f"| {p:.4f} | 1.00 |" in md
