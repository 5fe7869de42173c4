//! The recording-reading flags every analysis command shares (`--columns`, `--skip-missing`,
//! `--reverse`, `--timestamps`, `--scale`, `--valve`), mapped onto [`ReadOptions`].

use valve_bridge::recording::{ColumnMap, ReadOptions};

/// How to read the input recording.
#[derive(clap::Args, Debug, Clone)]
pub(crate) struct RecordingArgs {
    /// Column mapping, e.g. `t=t_s,op=LC74_20CV_pct,vp=LC74_20X_pct` (defaults t_s, op_pct, vp_pct).
    #[arg(long)]
    columns: Option<String>,
    /// Drop rows with empty or NaN cells (counted in a warning) instead of failing.
    #[arg(long)]
    skip_missing: bool,
    /// The file lists the newest row first.
    #[arg(long)]
    reverse: bool,
    /// The time column holds timestamps `YYYY-MM-DD HH:MM:SS`, not seconds.
    #[arg(long)]
    timestamps: bool,
    /// Multiply O_P and V_P by this factor (100 for fractions of full travel).
    #[arg(long, default_value_t = 1.0)]
    scale: f64,
    /// Of a log directory holding several valves' logs, the valve to read (its `[[valve]]
    /// name`).
    #[arg(long, value_name = "NAME")]
    valve: Option<String>,
}

impl RecordingArgs {
    /// The reader options these flags ask for.
    pub(crate) fn options(&self) -> anyhow::Result<ReadOptions> {
        let columns = match &self.columns {
            Some(s) => s.parse::<ColumnMap>()?,
            None => ColumnMap::default(),
        };
        Ok(ReadOptions {
            columns,
            skip_missing: self.skip_missing,
            reverse_sorted: self.reverse,
            timestamps: self.timestamps,
            scale: self.scale,
            valve: self.valve.clone(),
            ..ReadOptions::default()
        })
    }
}
