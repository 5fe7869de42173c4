"""valve_bridge against the CLI: the same recordings, the same JSON, the same errors."""

import threading
import time

import numpy as np
import pandas as pd
import pytest

import valve_bridge as vb
from conftest import CASES, ROOT, cli, cli_json

CLEAN = CASES / "pub_clean_rs.csv"
ASYM = CASES / "pub_asym_rs.csv"


def test_a_file_a_frame_and_arrays_give_the_same_recording():
    rec = vb.read(str(CLEAN))
    assert len(rec) == 60000 and rec.sample_period == 0.01
    assert isinstance(rec.op, np.ndarray) and rec.vp.shape == (60000,)
    df = pd.read_csv(CLEAN)
    from_df = vb.from_frame(df)
    np.testing.assert_array_equal(from_df.vp, rec.vp)
    from_arrays = vb.from_arrays(df.op_pct, df.vp_pct, sample_period=0.01)
    np.testing.assert_allclose(from_arrays.t, rec.t - rec.t[0], atol=1e-9)
    assert vb.steps(from_df) == vb.steps(rec)


def test_errors_are_the_cli_lines():
    code, _, err = cli("steps", ROOT / "Cargo.toml")
    assert code == 1
    with pytest.raises(vb.Error) as e:
        vb.read(str(ROOT / "Cargo.toml"))
    assert err.strip() == f"valve-bridge: error: {e.value}"
    with pytest.raises(vb.Error, match="no column 'POS'"):
        vb.from_frame(pd.DataFrame({"t_s": [0.0, 1.0], "op_pct": [1.0, 2.0]}), vp="POS")
    with pytest.raises(vb.Error, match=r"t\[2\] = 1 s is not after"):
        vb.from_arrays([1, 2, 3], t=[0, 1, 1])
    short = vb.from_arrays(np.full(100, 50.0), np.full(100, 50.0), sample_period=0.01)
    with pytest.raises(vb.Error, match="diagnosis needs at least 20 s of data"):
        vb.diagnose(short)
    with pytest.raises(vb.Error, match="models"):
        vb.identify(short, models=["nonsense"])


def test_steps_and_identify_match_the_cli_json():
    rec = vb.read(str(ASYM))
    assert vb.steps(rec) == cli_json("steps", ASYM, "--json")
    mine = vb.identify(rec, models=["fopdt"], windows="10-200")
    theirs = cli_json("identify", ASYM, "--models", "fopdt", "--windows", "10-200", "--json")
    for d in (mine, theirs):
        d.pop("elapsed_s")
    assert mine == theirs
    assert [r["model"] for r in mine["rows"]] == ["modelless", "delayed", "fopdt"]


def test_diagnose_matches_the_cli_and_writes_its_files(tmp_path):
    rec = vb.read(str(ASYM))
    d = vb.diagnose(rec, out=str(tmp_path))
    assert d == cli_json("diagnose", ASYM, "--json")
    assert [f["effect"] for f in d["findings"]] == ["asymmetry"]
    final = vb.Model.load(str(tmp_path / "model.toml"))
    assert final.kind == "pincart2"
    assert (tmp_path / "report.html").read_text().startswith("<!doctype html>")


def test_models_load_save_and_simulate_like_the_cli(tmp_path):
    m = vb.Model.load(str(ROOT / "config" / "models" / "pincart2.toml"))
    m.save(str(tmp_path / "m.toml"))
    again = vb.Model.load(str(tmp_path / "m.toml"))
    assert again.to_toml() == m.to_toml() == vb.Model.from_toml(m.to_toml()).to_toml()
    rec = vb.read(str(CLEAN))
    sim = vb.simulate(m, rec)
    code, _, err = cli("simulate", "--model", tmp_path / "m.toml", "--input", CLEAN, "--out", tmp_path / "s.csv")
    assert code == 0, err
    np.testing.assert_array_equal(sim, pd.read_csv(tmp_path / "s.csv").vp_pct.to_numpy())
    step = vb.simulate(str(tmp_path / "m.toml"), np.r_[np.full(100, 20.0), np.full(400, 30.0)], 0.01)
    assert step[0] == 20.0 and 29.0 < step[-1] <= 30.0
    with pytest.raises(vb.Error, match="<text>:2: pincart2: missing field `p_gain_per_s`"):
        vb.Model.from_toml("model = \"pincart2\"\n[pincart2]\nc_p = -5\n")


def test_long_work_releases_the_gil():
    rec = vb.read(str(ASYM))
    worker = threading.Thread(target=vb.identify, args=(rec,), kwargs={"models": ["fopdt"]})
    spins = 0
    worker.start()
    started = time.perf_counter()
    while worker.is_alive():
        spins += 1
    busy = time.perf_counter() - started
    worker.join()
    # Held, the GIL would stop this loop for the whole fit (a second or more).
    assert busy > 0.2 and spins > 10000, (busy, spins)
