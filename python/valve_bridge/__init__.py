"""valve-bridge for Python: the library the ``valve-bridge`` CLI runs, on recordings held as
files, numpy arrays or pandas DataFrames.

Results are plain Python objects shaped as the CLI's ``--json`` documents (``identify``,
``steps``, ``diagnose``, the fleet summaries); signals are numpy arrays. Long work releases the
GIL, so threads (and Dask workers) run in parallel. Every refusal raises :class:`Error` with the
CLI's one-line message.
"""

import numpy as np

from ._native import (
    Error,
    Model,
    Recording,
    diagnose,
    diagnose_valve,
    fleet_jobs,
    fleet_report,
    fleet_run,
    identify,
    read,
    steps,
)
from . import _native

__all__ = [
    "Error",
    "Model",
    "Recording",
    "diagnose",
    "diagnose_valve",
    "fleet_jobs",
    "fleet_report",
    "fleet_run",
    "from_arrays",
    "from_frame",
    "identify",
    "read",
    "simulate",
    "steps",
]


def _floats(x):
    return np.ascontiguousarray(np.asarray(x, dtype=np.float64).ravel())


def from_arrays(op, vp=None, t=None, sample_period=None):
    """A :class:`Recording` from arrays of O_P and V_P (in %), with times ``t`` in seconds or a
    constant ``sample_period`` in seconds (samples at 0, dt, 2 dt, ...)."""
    op = _floats(op)
    if t is None:
        if sample_period is None:
            raise Error("give the sample times t (s) or the sample_period (s)")
        t = np.arange(len(op), dtype=np.float64) * float(sample_period)
    vp = _floats([] if vp is None else vp)
    return _native._from_arrays(_floats(t), op, vp)


def from_frame(df, op="op_pct", vp="vp_pct", t="t_s", sample_period=None):
    """A :class:`Recording` from a pandas DataFrame's columns ``op``, ``vp`` (None: no V_P) and
    ``t`` (seconds); with ``sample_period`` the times are not read (e.g. a DatetimeIndex)."""
    missing = [c for c in (op, vp, None if sample_period else t) if c and c not in df.columns]
    if missing:
        raise Error(f"no column {', '.join(map(repr, missing))}; the frame has {list(df.columns)}")
    return from_arrays(
        df[op].to_numpy(),
        None if vp is None else df[vp].to_numpy(),
        None if sample_period else df[t].to_numpy(),
        sample_period,
    )


def simulate(model, op, sample_period=None, vp0=None):
    """V_P of ``model`` (a :class:`Model` or a model file's path) driven by ``op``: a
    :class:`Recording` (its O_P and period, starting at its first V_P) or an array with
    ``sample_period`` in seconds (starting at rest at the first O_P unless ``vp0``)."""
    if not isinstance(model, Model):
        model = Model.load(str(model))
    if isinstance(op, Recording):
        rec = op
        op, sample_period = rec.op, rec.sample_period
        if vp0 is None and len(rec.vp):
            vp0 = rec.vp[0]
    op = _floats(op)
    if sample_period is None:
        raise Error("give the sample_period (s) of the O_P array")
    if len(op) == 0:
        return np.empty(0)
    return _native._simulate(model, op, float(sample_period), float(op[0] if vp0 is None else vp0))
