//! Loop timing benchmark: runs the real daemon loop (embedded default config: emulated pin-cart
//! II, random steps, 100 Hz, real clock, logging to a temporary directory) for a fixed time and
//! reports the timing error |actual - scheduled| (p50, p99, max) and the missed cycles; then the
//! same with the two valves of `config/two-valves.toml` in each cycle, and the ratio of the two
//! p99s (the two-valve loop should stay within 2x of the single one on an idle machine); then
//! the two valves with `[health]` (a 60 s window each minute) without and with `[diagnosis]`
//! (a 60 s window each minute, and beside it a diagnosis of 5 minutes of random steps run back
//! to back on the same pool at the same lowest priority, so diagnosis works through the whole
//! run), alternated `VB_BENCH_REPEATS` times (default 3): each run's
//! p99, the ratio of the medians, and how many runs with live diagnosis stay within the range
//! of those without, the bench's noise (live diagnosis should cost the loop nothing beyond it).
//!
//! `cargo bench --bench loop_timing`; `VB_BENCH_SECS` sets the time of each run (default 60 s);
//! `VB_BENCH_PRIORITY=N` runs the loop thread under SCHED_FIFO priority N (`[loop] realtime_priority`).
//! `VB_BENCH_TOKIO=1` also measures `tokio::time::interval` (MissedTickBehavior::Skip) over the
//! same time, the baseline the daemon's schedule replaces.

use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::Arc;
use std::thread::JoinHandle;
use std::time::{Duration, Instant};

use hdrhistogram::Histogram;
use valve_bridge::daemon::config::{DiagnosisConfig, HealthConfig};
use valve_bridge::daemon::{self, Config, RunOptions};
use valve_bridge::metrics::stats::median;
use valve_bridge::model::{bundled, ModelKind};
use valve_bridge::synth::{self, Excitation};

fn main() -> Result<(), Box<dyn std::error::Error>> {
    let secs: f64 = match std::env::var("VB_BENCH_SECS") {
        Ok(v) => v.parse().map_err(|e| format!("VB_BENCH_SECS={v}: {e}"))?,
        Err(_) => 60.0,
    };
    let priority: u8 = match std::env::var("VB_BENCH_PRIORITY") {
        Ok(v) => v
            .parse()
            .map_err(|e| format!("VB_BENCH_PRIORITY={v}: {e}"))?,
        Err(_) => 0,
    };
    let repeats: usize = match std::env::var("VB_BENCH_REPEATS") {
        Ok(v) => v
            .parse()
            .map_err(|e| format!("VB_BENCH_REPEATS={v}: {e}"))?,
        Err(_) => 3,
    };
    println!("loop_timing: {secs} s at 100 Hz, real clock, SCHED_FIFO priority {priority}");
    let one = Config::embedded_default()?;
    let two = Config::from_toml(
        include_str!("../config/two-valves.toml"),
        std::path::Path::new("config/two-valves.toml"),
    )?;
    let mut p99 = Vec::new();
    for (what, mut config) in [("one valve", one), ("two valves", two.clone())] {
        config.loop_.realtime_priority = priority;
        p99.push(timed(what, config, secs)?);
    }
    println!(
        "p99 two valves / one valve: {:.2}",
        p99[1] / p99[0].max(f64::MIN_POSITIVE)
    );
    let mut watched = two;
    watched.loop_.realtime_priority = priority;
    watched.health = Some(HealthConfig {
        window_s: 60.0,
        ..HealthConfig::default()
    });
    let mut diagnosed = watched.clone();
    diagnosed.diagnosis = Some(DiagnosisConfig {
        window_s: 60.0,
        every_s: 60.0,
        ..DiagnosisConfig::default()
    });
    // Alternated, so that what the machine does meanwhile falls on both alike; the spread of
    // the runs without live diagnosis is the bench's noise. With it, a diagnosis also runs
    // back to back for the whole run (what a daemon that always has a window to diagnose does
    // beside its loop), not only the run's own one per minute.
    let (mut without, mut with) = (Vec::new(), Vec::new());
    for run in 1..=repeats {
        let what = format!("two valves, [health], run {run}/{repeats}");
        without.push(timed(&what, watched.clone(), secs)?);
        let stop = Arc::new(AtomicBool::new(false));
        let busy = busy_diagnosis(Arc::clone(&stop))?;
        let what = format!("two valves, [health] and [diagnosis], run {run}/{repeats}");
        let p99 = timed(&what, diagnosed.clone(), secs);
        stop.store(true, Ordering::Relaxed);
        let done = busy
            .join()
            .map_err(|_| "the diagnosing thread panicked")??;
        println!("  diagnoses beside the loop, back to back: {done}");
        with.push(p99?);
    }
    println!(
        "p99 without live diagnosis: {}; with: {}",
        list_us(&without),
        list_us(&with)
    );
    let ratio = median(&with).unwrap_or(f64::NAN)
        / median(&without).map_or(f64::NAN, |m| m.max(f64::MIN_POSITIVE));
    println!(
        "p99 with live diagnosis / without, medians: {:.2}; with inside the range without: {} of {}",
        ratio,
        with.iter()
            .filter(|p| **p <= without.iter().copied().fold(0.0, f64::max))
            .count(),
        with.len()
    );
    if std::env::var("VB_BENCH_TOKIO").is_ok_and(|v| v == "1") {
        let (hist, missed) = tokio_interval(secs)?;
        println!(
            "tokio::time::interval: {} ticks, {} missed, timing error p50 {:.2} us, p99 {:.2} us, max {:.2} us",
            hist.len(),
            missed,
            hist.value_at_quantile(0.5) as f64 / 1e3,
            hist.value_at_quantile(0.99) as f64 / 1e3,
            hist.max() as f64 / 1e3
        );
    }
    Ok(())
}

/// Runs `config` for `secs`, prints its timing and returns its p99, µs.
fn timed(what: &str, config: Config, secs: f64) -> Result<f64, Box<dyn std::error::Error>> {
    let dir = tempfile::tempdir()?;
    let summary = daemon::start(
        config,
        RunOptions {
            duration_s: Some(secs),
            log_dir: Some(dir.path().to_path_buf()),
            virtual_clock: false,
            progress: false,
            require_device: false,
            analysis: valve_bridge::live::analysis(),
        },
    )?
    .finish()?;
    let v = summary.valves.first().ok_or("the run has no valve")?;
    let s = &v.stats;
    if let Some(d) = &v.diagnosis {
        println!(
            "  live diagnosis: {} diagnoses of the first valve",
            d.diagnoses
        );
    }
    println!(
        "daemon loop, {what}: {} samples per valve, {} missed cycles, timing error p50 {:.2} us, p99 {:.2} us, max {:.2} us",
        v.samples(),
        v.missed(),
        s.lateness_us(0.5),
        s.lateness_us(0.99),
        s.max_lateness_us()
    );
    Ok(s.lateness_us(0.99))
}

/// Diagnoses 5 minutes of pin-cart II on random steps over and over, as the daemon's live
/// diagnosis does (its function, its pool, the lowest priority), until `stop`; returns how many
/// it finished.
fn busy_diagnosis(stop: Arc<AtomicBool>) -> Result<JoinHandle<Result<usize, String>>, String> {
    let spec = bundled(ModelKind::Pincart2);
    let rec = synth::generate(&spec, Excitation::RandomSteps, 300.0, 0.01, 0.05, 7)
        .map_err(|e| e.to_string())?;
    let diagnose = valve_bridge::live::analysis()
        .diagnose
        .ok_or("the analysis layer has no diagnosis")?;
    Ok(std::thread::spawn(move || {
        valve_bridge::priority::lowest_priority();
        let mut done = 0;
        while !stop.load(Ordering::Relaxed) {
            diagnose(&rec.view(), None, None)?;
            done += 1;
        }
        Ok(done)
    }))
}

/// `v` in µs, one decimal, comma-separated.
fn list_us(v: &[f64]) -> String {
    let each: Vec<String> = v.iter().map(|p| format!("{p:.1}")).collect();
    format!("{} us", each.join(", "))
}

/// |tick - scheduled| of a 10 ms `tokio::time::interval` over `secs`, and the ticks it skipped.
fn tokio_interval(secs: f64) -> Result<(Histogram<u64>, u64), Box<dyn std::error::Error>> {
    let rt = tokio::runtime::Builder::new_current_thread()
        .enable_all()
        .build()?;
    let mut hist = Histogram::<u64>::new_with_bounds(1, 60_000_000_000, 3)?;
    let period = Duration::from_millis(10);
    let n = (secs * 100.0).round() as u64;
    let missed = rt.block_on(async {
        let t0 = tokio::time::Instant::now() + period;
        let mut interval = tokio::time::interval_at(t0, period);
        interval.set_missed_tick_behavior(tokio::time::MissedTickBehavior::Skip);
        let mut ticks = 0u64;
        let mut last_slot = None;
        let mut missed = 0;
        while ticks < n {
            interval.tick().await;
            let now = Instant::now();
            let since = now.duration_since(t0.into_std());
            // The nearest grid slot and the error to it.
            let slot = (since.as_nanos() as f64 / period.as_nanos() as f64).round() as u64;
            let sched = t0.into_std() + period * slot as u32;
            let err = if now >= sched {
                now - sched
            } else {
                sched - now
            };
            hist.saturating_record(err.as_nanos().max(1) as u64);
            if let Some(prev) = last_slot {
                missed += slot.saturating_sub(prev + 1);
            }
            last_slot = Some(slot);
            ticks += 1;
        }
        missed
    });
    Ok((hist, missed))
}
