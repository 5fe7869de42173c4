//! Scores of the blind diagnosis benchmark: the confusion matrix of true effect against first
//! finding, precision and recall over all findings (a finding of a planned effect too faint to
//! label counts neither way), the false-finding rate on healthy valves (nothing planned),
//! the held-out gain, the smallest size found reliably per excitation, the time per case, the
//! curve of healthy valves with a finding against recall over the materiality threshold, how
//! often the interval of a finding's size holds the physical truth, and the overall figures
//! against their targets; each over the valves it is given (the bench hands it each family
//! apart). Only arithmetic and printing; no diagnosis.

use valve_bridge::diagnose::{Effect, Size};

use crate::cases::Truth;

/// What one case was and what diagnosis said about it.
#[derive(Debug, Clone)]
pub(crate) struct Outcome {
    pub family: &'static str,
    pub excitation: &'static str,
    pub labels: Vec<Effect>,
    /// Each planned effect with the size it was drawn at.
    pub sizes: Vec<(Effect, f64)>,
    /// The physical size of each label.
    pub truth: Vec<Truth>,
    /// The effects found, in the order diagnosis found them.
    pub findings: Vec<Effect>,
    /// The size of each finding, with its interval.
    pub sized: Vec<(Effect, Size)>,
    pub baseline_heldout_sse: f64,
    pub final_heldout_sse: f64,
    pub seconds: f64,
    /// CPU time of the diagnosis in all its threads, s.
    pub cpu_seconds: f64,
    /// Every finding and trace: its effect, its size over what is worth maintenance, the share
    /// of the held-out error it removes (1 for stick-slip judged by its slips, which the
    /// held-out error cannot judge).
    pub items: Vec<Item>,
}

/// A finding or a trace, weighed.
#[derive(Debug, Clone, Copy)]
pub(crate) struct Item {
    pub effect: Effect,
    /// Its worth at the less material end of its interval, what materiality is judged on.
    pub worth_low: f64,
    pub heldout_share: f64,
}

impl Outcome {
    /// Whether `effect` was planned in the valve but did not show enough in its recording to be
    /// labelled: the physics is there, so finding it is not a false finding, and missing it is
    /// not a miss.
    pub(crate) fn faint(&self, effect: Effect) -> bool {
        !self.labels.contains(&effect) && self.sizes.iter().any(|(e, _)| *e == effect)
    }

    /// A valve with nothing planned: every parameter inside its healthy range.
    pub(crate) fn healthy(&self) -> bool {
        self.labels.is_empty() && self.sizes.is_empty()
    }

    /// 1 - final / baseline held-out SSE.
    pub(crate) fn gain(&self) -> f64 {
        1.0 - self.final_heldout_sse / self.baseline_heldout_sse
    }
}

/// Targets the method is judged against.
pub(crate) const FIRST_HIT_TARGET: f64 = 0.94;
pub(crate) const PRECISION_TARGET: f64 = 0.95;
pub(crate) const RECALL_TARGET: f64 = 0.90;
pub(crate) const HEALTHY_FALSE_TARGET: f64 = 0.02;
pub(crate) const GAIN_TARGET: f64 = 0.50;
pub(crate) const SECONDS_TARGET: f64 = 15.0;
/// CPU time a recording of [`crate::cases::DURATION_S`] (10 minutes) may cost, s, in all threads.
pub(crate) const CPU_SECONDS_TARGET: f64 = 10.0;
/// Share of cases a size bin must find to count as found reliably.
pub(crate) const RELIABLE: f64 = 0.80;
/// Share of findings whose 90 % interval must hold the physical truth, per effect.
pub(crate) const COVERAGE_TARGET: f64 = 0.80;
/// Relative rounding an interval's ends may differ from the truth by and still hold it: a
/// lattice read off the recording equals the drawn one to the last digits.
const ROUNDING: f64 = 1e-9;

fn short(e: Option<Effect>) -> &'static str {
    match e {
        None => "none",
        Some(Effect::DeadTime) => "dt",
        Some(Effect::Backlash) => "bkl",
        Some(Effect::StateDependentDelay) => "sdd",
        Some(Effect::SlewRate) => "slew",
        Some(Effect::Asymmetry) => "asym",
        Some(Effect::MinSpeed) => "mins",
        Some(Effect::Stiction) => "stic",
        Some(Effect::Deadband) => "db",
        Some(Effect::Saturation) => "sat",
        Some(Effect::Quantization) => "qnt",
        Some(Effect::Calibration) => "cal",
    }
}

fn classes() -> Vec<Option<Effect>> {
    let mut c: Vec<Option<Effect>> = Effect::ALL.iter().map(|e| Some(*e)).collect();
    c.push(None);
    c
}

fn median(mut v: Vec<f64>) -> f64 {
    v.retain(|x| x.is_finite());
    if v.is_empty() {
        return f64::NAN;
    }
    v.sort_by(f64::total_cmp);
    let n = v.len();
    if n % 2 == 1 {
        v[n / 2]
    } else {
        0.5 * (v[n / 2 - 1] + v[n / 2])
    }
}

fn pct(num: usize, den: usize) -> String {
    if den == 0 {
        "  -".into()
    } else {
        format!("{:.0} %", 100.0 * num as f64 / den as f64)
    }
}

/// The confusion matrix over valves with at most one effect, then the two-effect valves.
pub(crate) fn print_confusion(all: &[Outcome]) {
    println!("\nConfusion matrix, valves with at most one effect (rows: true effect, columns: first finding):");
    let cls = classes();
    print!("{:>6}", "");
    for c in &cls {
        print!("{:>6}", short(*c));
    }
    println!("{:>7}", "cases");
    for row in &cls {
        let cases: Vec<&Outcome> = all
            .iter()
            .filter(|o| o.labels.len() <= 1 && o.labels.first().copied() == *row)
            .collect();
        print!("{:>6}", short(*row));
        for col in &cls {
            let n = cases
                .iter()
                .filter(|o| o.findings.first().copied() == *col)
                .count();
            print!("{:>6}", if n == 0 { ".".into() } else { n.to_string() });
        }
        println!("{:>7}", cases.len());
    }
    let doubles: Vec<&Outcome> = all.iter().filter(|o| o.labels.len() >= 2).collect();
    let first = doubles
        .iter()
        .filter(|o| o.findings.first().is_some_and(|f| o.labels.contains(f)))
        .count();
    let both = doubles
        .iter()
        .filter(|o| o.labels.iter().all(|l| o.findings.contains(l)))
        .count();
    println!(
        "Two effects at once: first finding names one of them in {first}/{} valves, both found in {both}/{}",
        doubles.len(),
        doubles.len()
    );
}

/// Of the valves labelled with `effect`: how many, how many got a finding of it; and the
/// valves that got it without it (a faint planned effect counts neither way).
fn tally(all: &[&Outcome], effect: Effect) -> (usize, usize, usize) {
    let with: Vec<&&Outcome> = all.iter().filter(|o| o.labels.contains(&effect)).collect();
    let hits = with.iter().filter(|o| o.findings.contains(&effect)).count();
    let false_ = (all.iter())
        .filter(|o| !o.labels.contains(&effect) && !o.faint(effect) && o.findings.contains(&effect))
        .count();
    (with.len(), hits, false_)
}

/// A share as its numerator and denominator.
#[derive(Debug, Clone, Copy, PartialEq)]
pub(crate) struct Share {
    pub num: usize,
    pub den: usize,
}

impl Share {
    /// The share, 0 of nothing.
    pub(crate) fn rate(self) -> f64 {
        self.num as f64 / self.den.max(1) as f64
    }
}

/// The figures a group of valves is judged by (see the targets above).
#[derive(Debug, Clone, Copy, PartialEq)]
pub(crate) struct Headline {
    /// Valves with an effect whose first finding names one of them.
    pub first: Share,
    /// Findings of a labelled effect over all findings (faint planned effects aside).
    pub precision: Share,
    /// Labels found over labels.
    pub recall: Share,
    /// Healthy valves with any finding.
    pub healthy_flagged: Share,
    /// Valves with a deadband and no stick-slip that were named stiction.
    pub deadband_as_stiction: Share,
}

/// The [`Headline`] of `all`.
pub(crate) fn headline(all: &[&Outcome]) -> Headline {
    let (mut tp, mut fp, mut labelled) = (0, 0, 0);
    for e in Effect::ALL {
        let (with, hits, false_) = tally(all, e);
        (tp, fp, labelled) = (tp + hits, fp + false_, labelled + with);
    }
    let with: Vec<&&Outcome> = all.iter().filter(|o| !o.labels.is_empty()).collect();
    let first = (with.iter())
        .filter(|o| o.findings.first().is_some_and(|f| o.labels.contains(f)))
        .count();
    let healthy: Vec<&&Outcome> = all.iter().filter(|o| o.healthy()).collect();
    let flagged = healthy.iter().filter(|o| !o.findings.is_empty()).count();
    let deadband: Vec<&&Outcome> = (all.iter())
        .filter(|o| o.labels.contains(&Effect::Deadband) && !o.labels.contains(&Effect::Stiction))
        .collect();
    let as_stiction = (deadband.iter())
        .filter(|o| o.findings.contains(&Effect::Stiction))
        .count();
    Headline {
        first: Share {
            num: first,
            den: with.len(),
        },
        precision: Share {
            num: tp,
            den: tp + fp,
        },
        recall: Share {
            num: tp,
            den: labelled,
        },
        healthy_flagged: Share {
            num: flagged,
            den: healthy.len(),
        },
        deadband_as_stiction: Share {
            num: as_stiction,
            den: deadband.len(),
        },
    }
}

/// Precision and recall per effect over all findings.
pub(crate) fn print_precision_recall(all: &[Outcome]) {
    println!("\nPer effect, over all findings:");
    println!(
        "{:<22}{:>8}{:>8}{:>8}{:>11}{:>8}",
        "effect", "labelled", "found", "false", "precision", "recall"
    );
    let all: Vec<&Outcome> = all.iter().collect();
    for e in Effect::ALL {
        let (with, hits, false_) = tally(&all, e);
        println!(
            "{:<22}{:>8}{:>8}{:>8}{:>11}{:>8}",
            e.name(),
            with,
            hits,
            false_,
            pct(hits, hits + false_),
            pct(hits, with)
        );
    }
}

/// Bins of the sizes of `effect` over `all` (three log-spaced bins between the extremes).
fn size_bins(all: &[Outcome], effect: Effect) -> Vec<f64> {
    let sizes: Vec<f64> = all
        .iter()
        .flat_map(|o| o.sizes.iter())
        .filter(|(e, s)| *e == effect && *s > 0.0)
        .map(|(_, s)| *s)
        .collect();
    let lo = sizes.iter().copied().fold(f64::INFINITY, f64::min);
    let hi = sizes.iter().copied().fold(0.0, f64::max);
    if !lo.is_finite() || hi <= lo {
        return vec![lo, hi];
    }
    (0..=3)
        .map(|k| (lo.ln() + (hi.ln() - lo.ln()) * k as f64 / 3.0).exp())
        .collect()
}

/// Per effect and excitation: the lower edge of the smallest size bin found in at least 80 %
/// of its valves (found: the effect is among the findings).
pub(crate) fn print_smallest_found(all: &[Outcome], excitations: &[&str]) {
    println!("\nSmallest size found in >= 80 % of valves, per excitation (size bin lower edge, found/valves in it):");
    print!("{:<30}", "effect (size unit)");
    for x in excitations {
        print!("{:>17}", x);
    }
    println!();
    for e in Effect::ALL {
        let edges = size_bins(all, e);
        print!("{:<30}", format!("{} ({})", e.name(), unit(e)));
        for x in excitations {
            let mut cell = "-".to_string();
            for b in 0..edges.len().saturating_sub(1) {
                let (lo, hi) = (edges[b], edges[b + 1]);
                let last = b + 2 == edges.len();
                let inside: Vec<&Outcome> = all
                    .iter()
                    .filter(|o| o.excitation == *x && o.labels.contains(&e))
                    .filter(|o| {
                        o.sizes
                            .iter()
                            .any(|(f, s)| *f == e && *s >= lo && (*s < hi || (last && *s <= hi)))
                    })
                    .collect();
                let found = inside.iter().filter(|o| o.findings.contains(&e)).count();
                if !inside.is_empty() && found as f64 >= RELIABLE * inside.len() as f64 {
                    cell = format!("{lo:.3} ({found}/{})", inside.len());
                    break;
                }
            }
            print!("{cell:>17}");
        }
        println!();
    }
}

fn unit(e: Effect) -> &'static str {
    match e {
        Effect::DeadTime => "s",
        Effect::StateDependentDelay => "g",
        Effect::SlewRate => "%/s",
        Effect::MinSpeed => "q_min/K, %",
        Effect::Asymmetry => "ratio",
        Effect::Saturation => "stop from its end, %",
        _ => "%",
    }
}

/// Materiality thresholds of the curve, as multiples of the documented sizes.
const CURVE: [f64; 7] = [0.5, 0.75, 1.0, 1.25, 1.5, 2.0, 3.0];

impl Outcome {
    /// The effects named when what is worth maintenance is `m` times the documented sizes and
    /// a finding must remove `share` of the held-out error: the findings and traces of the
    /// diagnosis that weigh that much (one diagnosis per valve, so the later rounds are those
    /// of the default thresholds: an approximation away from them).
    fn named_at(&self, m: f64, share: f64) -> Vec<Effect> {
        (self.items.iter())
            .filter(|i| i.worth_low >= m && i.heldout_share >= share)
            .map(|i| i.effect)
            .collect()
    }
}

/// Healthy valves with a finding and recall at materiality `m` and held-out share `share`,
/// over `cases` (all, or one excitation).
fn at(cases: &[&Outcome], m: f64, share: f64) -> (usize, usize, usize, usize) {
    let healthy: Vec<&&Outcome> = cases.iter().filter(|o| o.healthy()).collect();
    let alarms = (healthy.iter())
        .filter(|o| !o.named_at(m, share).is_empty())
        .count();
    let (mut hits, mut labelled) = (0, 0);
    for o in cases {
        let named = o.named_at(m, share);
        labelled += o.labels.len();
        hits += o.labels.iter().filter(|l| named.contains(l)).count();
    }
    (alarms, healthy.len(), hits, labelled)
}

/// The curve of healthy valves with a finding against recall, over the materiality threshold
/// (overall and per excitation) and over the share of the held-out error a finding must
/// remove (at the documented sizes); `share` is the run's.
pub(crate) fn print_curve(all: &[Outcome], excitations: &[&str], share: f64) {
    println!(
        "\nHealthy valves with a finding / recall, over the materiality threshold (x the documented sizes; \
         from each valve's findings and traces):"
    );
    print!("{:<14}", "excitation");
    for m in CURVE {
        print!("{:>17}", format!("x{m}"));
    }
    println!();
    let mut rows: Vec<(&str, Vec<&Outcome>)> = vec![("all", all.iter().collect())];
    for x in excitations {
        rows.push((x, all.iter().filter(|o| o.excitation == *x).collect()));
    }
    for (name, cases) in &rows {
        print!("{name:<14}");
        for m in CURVE {
            let (a, h, hits, l) = at(cases, m, share);
            print!("{:>17}", format!("{} / {}", pct(a, h), pct(hits, l)));
        }
        println!();
    }
    println!("Over the share of the held-out error a finding must remove (x1 sizes):");
    for s in [0.0, 0.01, 0.02, 0.03, 0.05, 0.1] {
        let (a, h, hits, l) = at(&all.iter().collect::<Vec<_>>(), 1.0, s);
        println!(
            "  share >= {:>4.0} %: healthy with a finding {a}/{h} ({}), recall {hits}/{l} ({})",
            100.0 * s,
            pct(a, h),
            pct(hits, l)
        );
    }
}

/// How the sizes of one effect's findings compare with the physical truth of its labels.
#[derive(Debug, Clone, PartialEq)]
pub(crate) struct Coverage {
    /// The truth's size (`dead_time_s`, ...).
    pub name: &'static str,
    /// Labelled valves, those with a finding of the effect, and those whose finding is sized
    /// in the truth's unit (a friction band may be quoted as a crossing time).
    pub labelled: usize,
    pub found: usize,
    pub sized: usize,
    /// Of the sized ones, how many 90 % intervals hold the truth.
    pub holds: usize,
    /// The median of reported over true (NaN when none is sized).
    pub ratio: f64,
}

/// The [`Coverage`] of `effect` over `all`, or `None` when no valve is labelled with it.
pub(crate) fn coverage(all: &[Outcome], effect: Effect) -> Option<Coverage> {
    let truths: Vec<(&Outcome, &Truth)> = (all.iter())
        .flat_map(|o| {
            (o.truth.iter())
                .filter(move |t| t.effect == effect)
                .map(move |t| (o, t))
        })
        .collect();
    let name = truths.first()?.1.name;
    let found: Vec<(&Size, &Truth)> = (truths.iter())
        .filter_map(|(o, t)| {
            let size = o.sized.iter().find(|(f, _)| *f == effect)?;
            Some((&size.1, *t))
        })
        .collect();
    let same: Vec<&(&Size, &Truth)> = found.iter().filter(|(s, t)| s.name == t.name).collect();
    let slack = |x: f64| ROUNDING * x.abs();
    let holds = (same.iter())
        .filter(|(s, t)| s.low - slack(s.low) <= t.value && t.value <= s.high + slack(s.high))
        .count();
    Some(Coverage {
        name,
        labelled: truths.len(),
        found: found.len(),
        sized: same.len(),
        holds,
        ratio: median(same.iter().map(|(s, t)| s.value / t.value).collect()),
    })
}

/// Per effect, the [`Coverage`] of its findings' intervals over the truth.
pub(crate) fn print_coverage(all: &[Outcome]) {
    println!(
        "\nSizes against the physical truth (findings of a labelled effect; target: the interval holds it in >= {:.0} %):",
        100.0 * COVERAGE_TARGET
    );
    println!(
        "{:<22}{:<25}{:>9}{:>7}{:>7}{:>8}{:>10}{:>15}",
        "effect", "size", "labelled", "found", "sized", "holds", "coverage", "reported/true"
    );
    for e in Effect::ALL {
        let Some(c) = coverage(all, e) else {
            continue;
        };
        println!(
            "{:<22}{:<25}{:>9}{:>7}{:>7}{:>8}{:>10}{:>15}",
            e.name(),
            c.name,
            c.labelled,
            c.found,
            c.sized,
            c.holds,
            pct(c.holds, c.sized),
            if c.ratio.is_finite() {
                format!("{:.2}", c.ratio)
            } else {
                "-".into()
            }
        );
    }
}

/// The overall figures against their targets.
pub(crate) fn print_overall(all: &[Outcome]) {
    let h = headline(&all.iter().collect::<Vec<_>>());
    let with: Vec<&Outcome> = all.iter().filter(|o| !o.labels.is_empty()).collect();
    let faint: Vec<&Outcome> = (all.iter())
        .filter(|o| o.labels.is_empty() && !o.sizes.is_empty())
        .collect();
    let gain = median(with.iter().map(|o| o.gain()).collect());
    let median_max = |v: Vec<f64>| (median(v.clone()), v.iter().copied().fold(0.0, f64::max));
    let (t_med, t_max) = median_max(all.iter().map(|o| o.seconds).collect());
    println!(
        "\nHealthy valves with any finding: {}/{}",
        h.healthy_flagged.num, h.healthy_flagged.den
    );
    let planned_found = (faint.iter())
        .filter(|o| !o.findings.is_empty() && o.findings.iter().all(|f| o.faint(*f)))
        .count();
    let other = (faint.iter())
        .filter(|o| o.findings.iter().any(|f| !o.faint(*f)))
        .count();
    println!(
        "Valves whose planned effect was too faint to label: {}; finding only what was planned \
         in {planned_found}, something else in {other}",
        faint.len()
    );
    println!(
        "Valves with a deadband named stiction: {}/{}",
        h.deadband_as_stiction.num, h.deadband_as_stiction.den
    );
    println!("Time per case (diagnosis): median {t_med:.1} s, max {t_max:.1} s");
    let (c_med, c_max) = median_max(all.iter().map(|o| o.cpu_seconds).collect());
    println!("CPU per case (diagnosis, all threads): median {c_med:.1} s, max {c_max:.1} s");
    println!(
        "\nOverall, {} valves ({} with an effect, {} healthy, {} too faint to label):",
        all.len(),
        with.len(),
        h.healthy_flagged.den,
        faint.len()
    );
    let line = |what: &str, value: String, ok: bool, target: &str| {
        println!(
            "  {what:<52}{value:>9}   target {target:<8} {}",
            if ok { "met" } else { "MISSED" }
        );
    };
    let rates = [
        (
            "first finding names a true effect",
            h.first,
            FIRST_HIT_TARGET,
        ),
        ("precision over all findings", h.precision, PRECISION_TARGET),
        ("recall over all labels", h.recall, RECALL_TARGET),
    ];
    for (what, share, target) in rates {
        line(
            what,
            format!("{:.1} %", 100.0 * share.rate()),
            share.rate() >= target,
            &format!(">= {:.0} %", 100.0 * target),
        );
    }
    let false_rate = h.healthy_flagged.rate();
    line(
        "healthy valves with any finding",
        format!("{:.1} %", 100.0 * false_rate),
        false_rate <= HEALTHY_FALSE_TARGET,
        &format!("<= {:.0} %", 100.0 * HEALTHY_FALSE_TARGET),
    );
    line(
        "median held-out gain (valves with an effect)",
        format!("{:.1} %", 100.0 * gain),
        gain >= GAIN_TARGET,
        &format!(">= {:.0} %", 100.0 * GAIN_TARGET),
    );
    line(
        "time per case (max)",
        format!("{t_max:.1} s"),
        t_max <= SECONDS_TARGET,
        &format!("<= {SECONDS_TARGET:.0} s"),
    );
    line(
        "CPU per 10-minute recording (max)",
        format!("{c_max:.1} s"),
        c_max <= CPU_SECONDS_TARGET,
        &format!("<= {CPU_SECONDS_TARGET:.0} s"),
    );
}
