//! `accomp discover`: arguments, loading the record, printing and writing the report (the
//! discovery is [`crate::discover`], the simulation in the loop [`crate::discover::simulate`]).

use std::path::PathBuf;

use super::values::{ImageFormat, RecordFormat};
use super::LogLimitArgs;
use crate::discover::import::{self, DatasetOptions};
use crate::discover::simulate::{self, output, simulate_dataset, write_report, write_scenario};
use crate::discover::{discover_path, note_bad_rows, report, select};

/// Arguments of `accomp discover`.
#[derive(Debug, Clone, clap::Args)]
pub struct DiscoverArgs {
    /// The record: a log (docs/log-format.md), a gMetrology .tsf or the AQG CSV.
    pub log: PathBuf,
    /// Calibration table (`accomp fit -o`): the baseline becomes its prediction.
    #[arg(long)]
    pub calibration: Option<PathBuf>,
    /// Print one JSON object.
    #[arg(long)]
    pub json: bool,
    /// Write a Markdown report with figures into this directory.
    #[arg(long)]
    pub report: Option<PathBuf>,
    /// Image format of the report's figures.
    #[arg(long, value_enum, default_value = "png")]
    pub report_format: ImageFormat,
    /// Record format.
    #[arg(long, value_enum, default_value = "auto")]
    pub format: RecordFormat,
    /// Output column (default: first `output*`, `gravity*` or `a_i*` column).
    #[arg(long)]
    pub output: Option<String>,
    /// Bin to at most this many points before fitting.
    #[arg(long, default_value_t = 50_000)]
    pub max_points: usize,
    /// Compare the record with its simulated twin: what the simulation gets wrong, the cause,
    /// the extended simulator and the gain (docs/discovery.md, "Simulation in the loop").
    #[arg(long)]
    pub simulate: bool,
    /// Base scenario of the twin (default: derived from the record).
    #[arg(long, requires = "simulate")]
    pub scenario: Option<PathBuf>,
    /// Ensemble size of the twin (seeds 1..=N; default: 1 500 000 / the record's points,
    /// within 30..=100).
    #[arg(long, requires = "simulate", value_parser = simulate::parse_ensemble)]
    pub ensemble: Option<usize>,
    /// Write the extended scenario (TOML that `accomp simulate` runs) here.
    #[arg(long, requires = "simulate")]
    pub write_scenario: Option<PathBuf>,
    /// Write the calibration table with the errors of its temperature models corrected (needs
    /// `--calibration`; refused when none was found or the core's validator refuses the result).
    #[arg(long, requires = "calibration")]
    pub write_table: Option<PathBuf>,
    #[command(flatten)]
    pub limits: LogLimitArgs,
}

/// `accomp discover`.
pub fn run(args: &DiscoverArgs) -> anyhow::Result<()> {
    args.limits.apply();
    // Outputs proved writable before minutes of work, not after.
    crate::outputs::check_optional_file(args.write_scenario.as_deref())?;
    if let Some(d) = &args.report {
        crate::outputs::check_dir(d)?;
    }
    crate::outputs::check_optional_file(args.write_table.as_deref())?;
    if args.simulate {
        return run_simulate(args);
    }
    let table = match &args.calibration {
        Some(p) => {
            let bytes = crate::calibration_file::read_table_bytes(p)?;
            Some(
                accomp::table::CalibrationTable::decode(&bytes)
                    .map_err(|e| anyhow::anyhow!("{}: {e}", p.display()))?,
            )
        }
        None => None,
    };
    let opts = DatasetOptions {
        output: args.output.clone(),
        max_points: args.max_points,
        unit_per_g_from_calibration: None,
    };
    let (d, _bad) = discover_path(
        &args.log,
        args.format.0,
        &opts,
        table.as_ref(),
        &select::Config::default(),
    )
    .map_err(|e| match e {
        crate::discover::DiscoverError::Import(e) => in_file(&args.log, e),
        other => other.into(),
    })?;
    if let Some(dir) = &args.report {
        report::write_report(&d, dir, args.report_format.0)?;
    }
    // The report is printed first, so that a refusal to write the table can be read in it.
    if args.json {
        println!("{}", serde_json::to_string_pretty(&report::json(&d))?);
    } else {
        print!("{}", report::text(&d));
    }
    if let Some(p) = &args.write_table {
        let check = d.table_check.as_ref();
        match (check.and_then(|c| c.corrected.as_ref()), check) {
            (Some(t), _) => crate::outputs::write_file(p, &t.encode())?,
            (None, Some(c)) if c.refused.is_some() => anyhow::bail!(
                "--write-table {}: the corrected table is refused by the validator: {}",
                p.display(),
                c.refused.as_deref().unwrap_or_default()
            ),
            _ => anyhow::bail!(
                "--write-table {}: no error of the table's temperature models was found; \
                 nothing written",
                p.display()
            ),
        }
    }
    Ok(())
}

/// A log's refusal said of its file (the reader names the line and the column).
fn in_file(path: &std::path::Path, e: import::ImportError) -> anyhow::Error {
    match e {
        import::ImportError::Log(e) => e.in_file(path).into(),
        other => other.into(),
    }
}

/// Loads the record as the discovery does (same binning and notes).
pub fn load(args: &DiscoverArgs) -> anyhow::Result<import::Dataset> {
    let (log, bad) = import::load_for_dataset(&args.log, args.format.0, args.output.as_deref())
        .map_err(|e| in_file(&args.log, e))?;
    let opts = DatasetOptions {
        output: args.output.clone(),
        max_points: args.max_points,
        unit_per_g_from_calibration: None,
    };
    let mut ds = import::dataset_from_log(&log, &opts)?;
    note_bad_rows(&mut ds, &bad);
    Ok(ds)
}

/// `accomp discover --simulate`.
fn run_simulate(args: &DiscoverArgs) -> anyhow::Result<()> {
    if args.calibration.is_some() {
        anyhow::bail!(
            "--simulate with --calibration: the twin takes its instrument from the record or \
             the base scenario (--scenario), not from a calibration table"
        );
    }
    let ds = load(args)?;
    let mut s = simulate_dataset(
        &ds,
        args.scenario.as_deref(),
        args.ensemble
            .unwrap_or_else(|| simulate::default_ensemble(ds.len())),
        &select::Config::default(),
    )?;
    write_scenario(&mut s, args.write_scenario.as_deref())?;
    if let Some(dir) = &args.report {
        write_report(&s, dir, args.report_format.0)?;
    }
    let unit = s.cause.dataset.output_unit.clone();
    if args.json {
        let mut j = report::json(&s.cause);
        if let serde_json::Value::Object(m) = &mut j {
            m.insert("simulation".into(), output::json(&s));
        }
        println!("{}", serde_json::to_string_pretty(&j)?);
    } else {
        print!("{}", output::text(&s, &unit));
        println!("\nCatalogue search on the measured − twin residual:\n");
        print!("{}", report::text(&s.cause));
    }
    Ok(())
}
