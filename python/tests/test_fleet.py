"""Fleet diagnosis through the package: on this machine (`fleet_run`) and on a Dask
LocalCluster of 2 workers (python/examples/dask_fleet.py), both giving `valve-bridge fleet`'s
summary."""

import json
import shutil
import sys

from dask.distributed import Client, LocalCluster

import valve_bridge as vb
from conftest import CASES, ROOT, cli

sys.path.insert(0, str(ROOT / "python" / "examples"))
import dask_fleet  # noqa: E402


def _fleet_dir(tmp_path):
    d = tmp_path / "recordings"
    d.mkdir()
    for name in ("pub_clean_rs.csv", "pub_asym_rs.csv"):
        shutil.copy(CASES / name, d / name)
    (d / "notes.csv").write_text("when,who\n1,me\n")
    return d


def _to_12_digits(x):
    """`x` with every float rounded to 12 significant digits: the CLI and the extension module
    are separate builds of the library, and a fitted figure may differ between them in its
    last bit."""
    if isinstance(x, float):
        return float(f"{x:.12g}")
    if isinstance(x, dict):
        return {k: _to_12_digits(v) for k, v in x.items()}
    if isinstance(x, list):
        return [_to_12_digits(v) for v in x]
    return x


def test_dask_and_the_cli_give_the_same_fleet(tmp_path):
    d = _fleet_dir(tmp_path)
    code, out, err = cli("fleet", d, "--out", tmp_path / "cli")
    assert code == 0, err
    expected = json.loads((tmp_path / "cli" / "summary.json").read_text())

    with LocalCluster(n_workers=2, threads_per_worker=1, processes=True) as cluster, Client(cluster) as client:
        summary = dask_fleet.diagnose_fleet(client, d, tmp_path / "dask")
    assert _to_12_digits(summary) == _to_12_digits(expected)
    assert [v["valve"] for v in summary["valves"]] == ["pub_asym_rs", "pub_clean_rs", "notes"]
    assert json.loads((tmp_path / "dask" / "summary.json").read_text())["valves"][0]["findings"] == ["asymmetry"]
    assert (tmp_path / "dask" / "valves" / "pub_asym_rs" / "report.html").is_file()
    assert (tmp_path / "dask" / "index.html").is_file()
    assert (tmp_path / "dask" / "summary.csv").read_text() == (tmp_path / "cli" / "summary.csv").read_text()


def test_fleet_run_and_listing_errors(tmp_path):
    d = _fleet_dir(tmp_path)
    (d / "pub_asym_rs.csv").unlink()
    summary = vb.fleet_run(str(d))
    assert [v["valve"] for v in summary["valves"]] == ["pub_clean_rs", "notes"]
    assert "no column" in summary["valves"][1]["error"]
    empty = tmp_path / "empty"
    empty.mkdir()
    try:
        vb.fleet_jobs(str(empty))
    except vb.Error as e:
        assert "no *.csv recordings" in str(e)
    else:
        raise AssertionError("an empty directory is refused")


def test_a_valve_row_quotes_the_figures_of_its_diagnosis(tmp_path):
    # One figure per quantity: the row diagnose_valve returns and vb.diagnose's document give
    # the same friction band, dead time and stroke speeds, and the row the findings' sizes.
    d = _fleet_dir(tmp_path)
    job = next(j for j in vb.fleet_jobs(str(d)) if j["valve"] == "pub_asym_rs")
    row = vb.diagnose_valve(job)
    f = vb.diagnose(vb.read(str(d / "pub_asym_rs.csv")))["figures"]
    assert row["friction_band_pct"] == f["friction_band_pct"]
    assert row["dead_time_s"] == f["dead_time_s"]
    assert row["stroke_speed_open_pct_per_s"] == f["opening_speed_pct_per_s"]
    assert row["stroke_speed_close_pct_per_s"] == f["closing_speed_pct_per_s"]
    assert len(row["sizes"]) == len(row["findings"]) == 1
