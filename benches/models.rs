//! Model stepping speed: nanoseconds per step for every model (the physical one too), and the time to simulate the
//! 41,300 samples of the paper's validation set. Run with `cargo bench --bench models`.
//! `benches/models_python.py` times the same pin-cart II loop in plain Python for comparison.

use std::hint::black_box;

use criterion::{criterion_group, criterion_main, BenchmarkId, Criterion, Throughput};
use valve_bridge::model::{bundled, ModelKind, Valve};

/// The paper's validation size (three windows, 413 s at 100 Hz).
const N: usize = 41_300;

/// Random-step O_P like the paper's experiment, deterministic (levels 20-97 %, holds 0-20 s).
fn random_steps(n: usize) -> Vec<f64> {
    let mut state: u64 = 0x2545_f491_4f6c_dd1d;
    let mut next = move || {
        state ^= state << 13;
        state ^= state >> 7;
        state ^= state << 17;
        (state >> 11) as f64 / (1u64 << 53) as f64
    };
    let mut out = Vec::with_capacity(n);
    while out.len() < n {
        let level = 20.0 + 77.0 * next();
        let hold = (next() * 2000.0) as usize + 1;
        out.extend(std::iter::repeat_n(level, hold.min(n - out.len())));
    }
    out
}

fn bench_models(c: &mut Criterion) {
    let op = random_steps(N);
    let mut per_step = c.benchmark_group("step");
    per_step.throughput(Throughput::Elements(1));
    for kind in ModelKind::EVERY {
        let mut valve = Valve::new(&bundled(kind), 0.01).expect("bundled model");
        valve.reset(op[0], op[0]);
        let mut k = 0usize;
        per_step.bench_function(BenchmarkId::from_parameter(kind.tag()), |b| {
            b.iter(|| {
                k = if k + 1 == N { 0 } else { k + 1 };
                black_box(valve.step(black_box(op[k])))
            })
        });
    }
    per_step.finish();

    let mut whole = c.benchmark_group("simulate_41300");
    whole.throughput(Throughput::Elements(N as u64));
    let mut out = vec![0.0; N];
    for kind in ModelKind::ALL {
        let mut valve = Valve::new(&bundled(kind), 0.01).expect("bundled model");
        whole.bench_function(BenchmarkId::from_parameter(kind.tag()), |b| {
            b.iter(|| {
                valve.simulate_into(black_box(&op), op[0], &mut out);
                black_box(out[N - 1])
            })
        });
    }
    whole.finish();
}

criterion_group!(benches, bench_models);
criterion_main!(benches);
