#!/usr/bin/env python3
"""The Table 1 fits of `valve-bridge identify` done with scipy.optimize, for comparison.

The models are the same equations as crates/core/src/model/ (delay line with fractional interpolation,
FOPDT, Choudhury stiction, pin-cart I and II, travel clamp), written as plain Python loops over
NumPy-loaded data (the models are recursive, so there is nothing to vectorise). Each model is
fitted with scipy.optimize.minimize(method="Nelder-Mead") in the same unit cube and bounds as
the Rust search (log scale for gains, time constants, speeds), from the same physical starts,
with a budget of simulations no smaller than the Rust search spent on that model, scored on all
samples. Prints time and SSE per model and in total next to the Rust figures.

Run after `cargo bench --bench fit_table1` (which writes the data and the Rust figures):
    python3 benches/fit_scipy.py [target/fit_bench/rust.json]
Needs numpy and scipy.
"""
import json
import math
import sys
import time

import numpy as np
from scipy.optimize import minimize


def delay_line(op, td, dt):
    """O_P delayed by td seconds, linear interpolation for the fraction (crates/core/src/model/delay.rs)."""
    s = max(td, 0.0) / dt
    r = round(s)
    if abs(s - r) < 1e-9:
        s = r
    whole = int(math.floor(s))
    frac = s - whole
    n = len(op)
    out = [0.0] * n
    first = op[0]
    for k in range(n):
        i0 = k - whole
        x0 = op[i0] if i0 >= 0 else first
        if frac == 0.0:
            out[k] = x0
        else:
            i1 = i0 - 1
            x1 = op[i1] if i1 >= 0 else first
            out[k] = (1.0 - frac) * x0 + frac * x1
    return out


def simulate(model, p, op, vp0, dt):
    """Free-run V_P of a model (dict of physical parameters) from rest at (op[0], vp0)."""
    u = delay_line(op, p.get("dead_time_s", 0.0), dt)
    n = len(u)
    out = [0.0] * n
    if model in ("modelless", "delayed"):
        return [min(max(x, 0.0), 100.0) for x in u]
    if model == "fopdt":
        a = 1.0 - math.exp(-dt / p["time_constant_s"])
        v = vp0
        for k in range(n):
            v += a * (u[k] - v)
            v = min(max(v, 0.0), 100.0)
            out[k] = v
        return out
    if model == "stiction":
        s, j = p["stickband_pct"], p["jumpband_pct"]
        y, u_prev, stuck, u_stuck, d = vp0, op[0], True, op[0], 0.0
        for k in range(n):
            x = u[k]
            du = x - u_prev
            u_prev = x
            moved = False
            if not stuck:
                if du != 0.0 and math.copysign(1.0, du) == d:
                    y = x - d * (s - j) / 2.0
                    moved = True
                else:
                    stuck = True
                    u_stuck = x - du
            if not moved:
                away = x - u_stuck
                sg = 0.0 if away == 0.0 else math.copysign(1.0, away)
                thr = j if sg == d else s
                if away != 0.0 and abs(away) > thr:
                    stuck = False
                    d = sg
                    y = x - sg * (s - j) / 2.0
            y = min(max(y, 0.0), 100.0)
            out[k] = y
        return out
    # pin-cart I and II
    two = model == "pincart2"
    half = (p["backlash_pct"] if not two else 1.0) / 2.0
    pk = p["p_gain_per_s"]
    v = y = vp0
    if two:
        dmax, dmin = p["dy_max_pct_per_s"], p["dy_min_pct_per_s"]
        ap, bp, cp = p["a_p"], p["b_p"], p["c_p"]
    for k in range(n):
        e = u[k] - v
        if not two:
            y += min(pk * dt, 1.0) * e
        elif e != 0.0:
            sg = 1.0 if e > 0 else -1.0
            rel = y - v
            if sg * rel >= half - 1e-12:
                speed = min(max(pk * abs(e), dmin), dmax)
                y += sg * min(speed * dt, abs(e))
            else:
                t = max((ap * v + bp) * v + cp, dt)
                y += sg * min(2.0 * half * dt / t, half - sg * rel)
        if y - v >= half:
            v = y - half
        elif y - v <= -half:
            v = y + half
        if v < 0.0 or v > 100.0:
            v = min(max(v, 0.0), 100.0)
            y = min(max(y, v - half), v + half)
        out[k] = v
    return out


def crossing_poly(t0, t50, t100):
    """a_p, b_p, c_p through the crossing times at 0/50/100 % (crates/analysis/src/fit/params.rs)."""
    a = (t100 - 2.0 * t50 + t0) / 5000.0
    b = (t50 - t0) / 50.0 - 50.0 * a
    c = t0
    if a > 0.0:
        v = -b / (2.0 * a)
        if 0.0 <= v <= 100.0:
            m = (a * v + b) * v + c
            if m < 0.0:
                c -= m
    return a, b, c


def params_of(model, x):
    """Physical parameter dict from the search vector (same layout as crates/analysis/src/fit/params.rs)."""
    if model == "delayed":
        return {"dead_time_s": x[0]}
    if model == "fopdt":
        return {"dead_time_s": x[0], "time_constant_s": x[1]}
    if model == "stiction":
        return {"dead_time_s": x[0], "stickband_pct": x[1], "jumpband_pct": x[1] * x[2]}
    if model == "pincart1":
        return {"dead_time_s": x[0], "backlash_pct": x[1], "p_gain_per_s": x[2]}
    a, b, c = crossing_poly(x[4], x[5], x[6])
    return {"dead_time_s": x[0], "p_gain_per_s": x[1], "dy_max_pct_per_s": x[2],
            "dy_min_pct_per_s": min(x[3], x[2]), "a_p": a, "b_p": b, "c_p": c}


def main():
    path = sys.argv[1] if len(sys.argv) > 1 else "target/fit_bench/rust.json"
    with open(path) as f:
        rust = json.load(f)
    data = np.genfromtxt(rust["csv"], delimiter=",", names=True)
    op = data["op_pct"].tolist()
    vp = data["vp_pct"].tolist()
    vp_np = np.asarray(vp)
    dt = rust["sample_period_s"]
    print(f"{len(op)} samples; Rust Table 1 median {rust['median_s']:.3f} s")
    total = 0.0
    for m in rust["models"]:
        model, defs = m["model"], m["defs"]
        if not defs:
            continue

        def to_x(uu):
            x = []
            for ui, d in zip(uu, defs):
                ui = min(max(ui, 0.0), 1.0)
                if d["log"]:
                    x.append(math.exp(math.log(d["lo"]) + ui * (math.log(d["hi"]) - math.log(d["lo"]))))
                else:
                    x.append(d["lo"] + ui * (d["hi"] - d["lo"]))
            return x

        def to_u(x):
            out = []
            for xi, d in zip(x, defs):
                if d["log"]:
                    out.append((math.log(max(xi, d["lo"])) - math.log(d["lo"])) / (math.log(d["hi"]) - math.log(d["lo"])))
                else:
                    out.append((xi - d["lo"]) / (d["hi"] - d["lo"]))
            return out

        def cost(uu):
            sim = np.asarray(simulate(model, params_of(model, to_x(uu)), op, vp[0], dt))
            return float(np.sum((vp_np - sim) ** 2))

        budget = max(m["simulations"] // len(m["starts"]), 20)
        t0 = time.perf_counter()
        best = (math.inf, None)
        for s in m["starts"]:
            r = minimize(cost, to_u(s), method="Nelder-Mead", bounds=[(0.0, 1.0)] * len(defs),
                         options={"maxfev": budget, "xatol": 1e-6, "fatol": 1e-9})
            if r.fun < best[0]:
                best = (r.fun, to_x(r.x))
        el = time.perf_counter() - t0
        total += el
        print(f"  {model:<9} scipy SSE {best[0]:>12.3f} in {el:7.1f} s "
              f"({len(m['starts'])} starts x {budget} simulations) | Rust SSE {m['sse']:>12.3f} "
              f"({m['simulations']} simulations)")
    print(f"scipy total {total:.1f} s vs Rust {rust['median_s']:.3f} s: {total / rust['median_s']:.0f}x")


if __name__ == "__main__":
    main()
