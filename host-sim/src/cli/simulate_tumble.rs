//! `accomp simulate-tumble`: a tumble log from true temperature models (the generator is
//! [`crate::tumble_sim`]).

use std::path::PathBuf;

use super::tumble::parse_axis;
use crate::tumble::RotationAxis;
use crate::tumble_sim::{self, TumbleSimConfig};

/// Generate a tumble log from true temperature models (the paper's printed order-2 models).
#[derive(clap::Args, Debug)]
pub struct SimulateTumbleArgs {
    /// Noise seed.
    #[arg(long, default_value_t = 1)]
    pub seed: u64,
    /// Output file (stdout when absent).
    #[arg(short = 'o', long = "output")]
    pub output: Option<PathBuf>,
    /// Equally spaced positions, starting at 0°.
    #[arg(long, default_value_t = 4)]
    pub positions: usize,
    /// Readings per position.
    #[arg(long, default_value_t = 10)]
    pub readings: usize,
    /// Temperatures (°C), comma-separated; default Table 1's 30..65 °C.
    #[arg(long, value_delimiter = ',')]
    pub temperatures: Vec<f64>,
    /// Tests per temperature.
    #[arg(long, default_value_t = 1)]
    pub repeats: usize,
    /// Axis along the head's rotation axis: output or pendulum.
    #[arg(long, value_parser = parse_axis, default_value = "pendulum")]
    pub rotation_axis: RotationAxis,
    /// Reading noise (V, 1σ).
    #[arg(long, default_value_t = 2e-6)]
    pub noise_v: f64,
    /// True index error (arcsec, 1σ).
    #[arg(long, default_value_t = 0.2)]
    pub index_error_arcsec: f64,
    /// Constant foundation tilt (arcsec).
    #[arg(long, default_value_t = 0.0)]
    pub tilt_arcsec: f64,
    /// True K3 (g/g³).
    #[arg(long, default_value_t = 0.0)]
    pub k3: f64,
    /// Bias drift (g/day).
    #[arg(long, default_value_t = 0.0)]
    pub bias_drift_g_per_day: f64,
    /// Omit the `test` column (tests then split by time gaps and angle restarts).
    #[arg(long)]
    pub no_test_column: bool,
}

/// Runs `accomp simulate-tumble`.
pub fn run(args: SimulateTumbleArgs) -> anyhow::Result<()> {
    crate::outputs::check_optional_file(args.output.as_deref())?;
    let SimulateTumbleArgs {
        seed,
        output,
        positions,
        readings,
        temperatures,
        repeats,
        rotation_axis,
        noise_v,
        index_error_arcsec,
        tilt_arcsec,
        k3,
        bias_drift_g_per_day,
        no_test_column,
    } = args;
    let mut cfg = TumbleSimConfig::table1_default(seed).map_err(anyhow::Error::msg)?;
    cfg.positions = positions;
    cfg.readings_per_position = readings;
    if !temperatures.is_empty() {
        cfg.temperatures_c = temperatures;
    }
    cfg.repeats = repeats;
    cfg.rotation_axis = rotation_axis;
    cfg.output_noise_v = noise_v;
    cfg.index_error_arcsec = index_error_arcsec;
    cfg.tilt_arcsec = tilt_arcsec;
    cfg.k3_g_per_g3 = k3;
    cfg.bias_drift_g_per_day = bias_drift_g_per_day;
    cfg.test_column = !no_test_column;
    let (log, _) = tumble_sim::simulate_tumble(&cfg).map_err(anyhow::Error::msg)?;
    match output {
        Some(path) => crate::outputs::write_file(&path, log.as_bytes())?,
        None => print!("{log}"),
    }

    Ok(())
}
