#!/usr/bin/env python3
"""Pin-cart II (same equations and parameters as crates/core/src/model/pincart.rs) as a plain Python loop.

Times 41,300 steps (the paper's validation size) to compare with `cargo bench --bench models`.
Run: python3 benches/models_python.py   (no third-party packages needed)
"""
import time

DT = 0.01
N = 41_300
# config/models/pincart2.toml
TD, PK, DYMAX, DYMIN, AP, BP, CP, BL = 0.38, 3.0, 20.0, 0.3, 0.00002, 0.003, 0.30, 1.0


def random_steps(n):
    state = 0x2545F4914F6CDD1D
    mask = (1 << 64) - 1
    out = []

    def nxt():
        nonlocal state
        state ^= (state << 13) & mask
        state ^= state >> 7
        state ^= (state << 17) & mask
        return (state >> 11) / float(1 << 53)

    while len(out) < n:
        level = 20.0 + 77.0 * nxt()
        hold = int(nxt() * 2000.0) + 1
        out.extend([level] * min(hold, n - len(out)))
    return out


def simulate(op):
    d = round(TD / DT)
    buf = [op[0]] * (d + 1)
    head = 0
    half = BL / 2.0
    v = y = op[0]
    out = [0.0] * len(op)
    for k, x in enumerate(op):
        head = (head + 1) % len(buf)
        buf[head] = x
        u = buf[(head - d) % len(buf)]
        e = u - v
        if e != 0.0:
            s = 1.0 if e > 0 else -1.0
            rel = y - v
            if s * rel >= half - 1e-12:
                speed = min(max(PK * abs(e), DYMIN), DYMAX)
                y += s * min(speed * DT, abs(e))
            else:
                t = max((AP * v + BP) * v + CP, DT)
                y += s * min(BL * DT / t, half - s * rel)
        if y - v >= half:
            v = y - half
        elif y - v <= -half:
            v = y + half
        v = min(max(v, 0.0), 100.0)
        out[k] = v
    return out


def main():
    op = random_steps(N)
    best = float("inf")
    for _ in range(5):
        t0 = time.perf_counter()
        simulate(op)
        best = min(best, time.perf_counter() - t0)
    print(f"python pin-cart II: {best * 1e3:.2f} ms for {N} steps = {best / N * 1e9:.0f} ns/step (best of 5)")


if __name__ == "__main__":
    main()
