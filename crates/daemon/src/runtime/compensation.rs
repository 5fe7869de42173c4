//! One valve's compensation in the loop: the [`Compensator`] of `[valve.compensation]` between
//! the source and the valve, its gauges, its warning when the guard switches it off, and what
//! the summary says of it.
//!
//! Each cycle the lane asks [`Compensation::setpoint`] for the set-point to send (rounded to the
//! log's precision, so the logged set-point is the one sent) and hands the row back to
//! [`Compensation::observe`]. Allocation-free on the loop thread, except for the one warning
//! when compensation is switched off. Not here: the compensation itself ([`vb_core::compensate`]).

use crate::config::ValveConfig;
use crate::error::DaemonError;
use crate::serve::exporter::CompensationMetrics;
use vb_core::compensate::guard;
use vb_core::compensate::{CompensateError, Compensator, Window};
use vb_core::model::ModelSpec;
use vb_core::recording::log_format::{round_pct, Sample};

/// What compensation did in a run, for the summary.
#[derive(Debug, Clone, PartialEq)]
pub struct CompensationReport {
    /// The parts that act, in words.
    pub described: String,
    /// Guard windows judged.
    pub windows: u64,
    /// The last window judged.
    pub last: Option<Window>,
    /// Loop time at which the guard switched compensation off, s.
    pub switched_off_s: Option<f64>,
    /// The window whose verdict switched it off.
    pub tripping: Option<Window>,
}

/// A valve's compensator and its figures.
#[derive(Debug)]
pub(crate) struct Compensation {
    valve: String,
    comp: Compensator,
    metrics: Option<CompensationMetrics>,
    report: CompensationReport,
    t_s: f64,
}

impl Compensation {
    /// The compensation `valve` configures, for a loop of period `period_s` sending set-points
    /// within `op_range`; None without `[valve.compensation]`.
    pub(crate) fn new(
        valve: &ValveConfig,
        period_s: f64,
        op_range: (f64, f64),
        metrics: Option<CompensationMetrics>,
    ) -> Result<Option<Self>, DaemonError> {
        let Some(cfg) = &valve.compensation else {
            return Ok(None);
        };
        let file = cfg.model_file.clone().unwrap_or_default();
        let model = ModelSpec::load(&file).map_err(CompensateError::from)?;
        let comp = Compensator::new(cfg, &model, period_s, op_range)?;
        let described = comp.describe();
        tracing::info!(
            valve = valve.label(),
            model = %file.display(),
            "compensation: {described}"
        );
        if let Some(m) = &metrics {
            m.publish(None, true);
        }
        Ok(Some(Compensation {
            valve: valve.label().to_string(),
            comp,
            metrics,
            report: CompensationReport {
                described,
                windows: 0,
                last: None,
                switched_off_s: None,
                tripping: None,
            },
            t_s: 0.0,
        }))
    }

    /// The set-point to send for the controller's O_P `op` at loop time `t_s`.
    pub(crate) fn setpoint(&mut self, op: f64, t_s: f64) -> f64 {
        self.t_s = t_s;
        round_pct(self.comp.setpoint(op, t_s))
    }

    /// Hands the guard the cycle's row; publishes a judged window, and warns once when the
    /// guard switches compensation off.
    pub(crate) fn observe(&mut self, row: &Sample) {
        let Some(w) = self.comp.observe(row.vp_pct) else {
            return;
        };
        self.report.windows += 1;
        self.report.last = Some(w);
        if let Some(m) = &self.metrics {
            m.publish(Some(&w), self.comp.active());
        }
        if !self.comp.active() && self.report.switched_off_s.is_none() {
            self.report.switched_off_s = Some(self.t_s);
            self.report.tripping = Some(w);
            let e = w.exceeded.map(|f| w.evidence_of(f)).unwrap_or_default();
            tracing::warn!(
                valve = %self.valve,
                "compensation switched off: over the last {} guard windows the valve's {} (chance \
                 makes as many holds exceed with probability {:.1e}); the controller's O_P is \
                 sent unchanged from now on",
                guard::WINDOWS_POOLED,
                tripped(&w),
                e.chance,
            );
        }
    }

    /// What compensation did.
    pub(crate) fn report(self) -> CompensationReport {
        self.report
    }
}

/// What tripped the guard in `w`, in words: the figure, in how many of the judged holds of the
/// pooled windows the valve exceeded its model, and by how much on average.
pub(crate) fn tripped(w: &Window) -> String {
    let Some(figure) = w.exceeded else {
        return "no figure exceeded".into();
    };
    let e = w.evidence_of(figure);
    format!(
        "{} beyond its model's in {} of {} holds, by {:.2} % on average",
        figure.name(),
        e.exceeding,
        e.holds,
        e.by_pct,
    )
}
