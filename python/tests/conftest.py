"""Shared paths for the valve_bridge tests: the repository, its shared recordings, and the
`valve-bridge` binary the results are compared with (built by `cargo build` or `cargo test`;
`VB_BIN` names another)."""

import json
import os
import pathlib
import subprocess

import pytest

ROOT = pathlib.Path(__file__).resolve().parents[2]
CASES = ROOT / "tests" / "data" / "cases"


def _binary():
    if os.environ.get("VB_BIN"):
        return os.environ["VB_BIN"]
    for profile in ("debug", "release"):
        p = ROOT / "target" / profile / "valve-bridge"
        if p.exists():
            return str(p)
    pytest.fail("no valve-bridge binary: run `cargo build` first or set VB_BIN")


def cli(*args):
    """Runs `valve-bridge ARGS`; returns (exit code, stdout, stderr)."""
    r = subprocess.run([_binary(), *map(str, args)], capture_output=True, text=True, cwd=ROOT)
    return r.returncode, r.stdout, r.stderr


def cli_json(*args):
    code, out, err = cli(*args)
    assert code == 0, err
    return json.loads(out)
