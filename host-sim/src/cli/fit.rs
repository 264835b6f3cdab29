//! `accomp fit`: arguments, reading the files, writing the report and the table (the fits are
//! in [`crate::fit`]).

use std::path::{Path, PathBuf};

use accomp::units::Celsius;

use crate::fit::{
    calibration_table, fit_table, parse_coefficient_table, parse_date, parse_orientation,
    parse_printed_models, render_text, today_utc, with_orientation, FitError, PAPER_MODELS_FILE,
};

/// Arguments of `accomp fit`.
#[derive(Debug, Clone, clap::Args)]
pub struct FitArgs {
    /// Coefficients-vs-temperature CSV (`temperature_c` plus coefficient columns).
    pub input: PathBuf,
    /// Print one JSON object instead of the text report.
    #[arg(long)]
    pub json: bool,
    /// Temperature at which sensitivities dK/dT are reported, °C.
    #[arg(long, default_value_t = 50.0)]
    pub at: f64,
    /// Write a calibration table (binary, docs/calibration-format.md) from the selected orders.
    #[arg(short = 'o', long = "output")]
    pub output: Option<PathBuf>,
    /// Reference temperature T0 of the linearized compensation, °C (the paper tested at 60 °C).
    #[arg(long, default_value_t = 60.0)]
    pub reference: f64,
    /// The paper's printed models (default: `paper_printed_temperature_models.csv` beside the
    /// input; skipped when absent there, an error when given here and absent).
    #[arg(long)]
    pub paper: Option<PathBuf>,
    /// Serial number stored in the table.
    #[arg(long, default_value = "")]
    pub serial: String,
    /// Calibration date stored in the table, YYYY-MM-DD (default: today, UTC).
    #[arg(long)]
    pub date: Option<String>,
    /// Test orientation stored in the table: 1g (input axis vertical), 0g (input axis
    /// horizontal, gravity on the pendulum axis) or a_i,a_p,a_o in g.
    #[arg(long, default_value = "1g")]
    pub orientation: String,
    /// Read a table above the reader's limits (20 million data lines, 64 MiB).
    #[arg(long)]
    pub allow_large: bool,
}

fn read(path: &Path) -> Result<String, FitError> {
    crate::log::reader::read_text_limited(path, crate::log::reader::MAX_SMALL_TEXT_BYTES).map_err(
        |e| FitError::Io {
            path: path.to_owned(),
            error: e.into_io(),
        },
    )
}

/// `accomp fit`.
pub fn run(args: &FitArgs) -> anyhow::Result<()> {
    crate::log::reader::set_allow_large(args.allow_large);
    crate::outputs::check_optional_file(args.output.as_deref())?;
    let at = Celsius(args.at);
    let table = parse_coefficient_table(&read(&args.input)?).map_err(|error| FitError::Csv {
        path: args.input.clone(),
        error,
    })?;
    let paper_path = match &args.paper {
        Some(p) => Some(p.clone()),
        None => {
            let beside = args
                .input
                .parent()
                .unwrap_or_else(|| Path::new("."))
                .join(PAPER_MODELS_FILE);
            beside.is_file().then_some(beside)
        }
    };
    let printed = match &paper_path {
        Some(p) => parse_printed_models(&read(p)?).map_err(|error| FitError::Csv {
            path: p.clone(),
            error,
        })?,
        None => Vec::new(),
    };
    for w in &table.warnings {
        eprintln!("warning: {}: {w}", args.input.display());
    }
    let report = fit_table(&table, &printed, at)?;
    if args.json {
        println!("{}", serde_json::to_string(&report)?);
    } else {
        print!("{}", render_text(&report, at, paper_path.as_deref()));
    }
    if let Some(out) = &args.output {
        let date = match &args.date {
            Some(d) => parse_date(d)?,
            None => today_utc(),
        };
        let scale = table.scale().map_err(|error| FitError::Csv {
            path: args.input.clone(),
            error,
        })?;
        let orientation = parse_orientation(&args.orientation)?;
        let cal = with_orientation(
            calibration_table(&report, scale, Celsius(args.reference), &args.serial, date)?,
            orientation,
        )?;
        crate::outputs::write_file(out, &cal.encode())?;
        // stderr, so that `--json` output stays a single JSON document on stdout.
        eprintln!(
            "wrote calibration table {} (id {:08x}, orders K0 {} K1 {} K2 {} δp {} δo {}, T0 {} °C, \
             orientation a_i {} g, a_p {} g, a_o {} g)",
            out.display(),
            cal.id(),
            cal.thermal.models.bias_g.order(),
            cal.thermal.models.scale_factor_v_per_g.order(),
            cal.thermal.models.nonlinearity_g_per_g2.order(),
            cal.thermal.models.misalignment_p_rad.order(),
            cal.thermal.models.misalignment_o_rad.order(),
            args.reference,
            cal.orientation.nominal_input.0,
            cal.orientation.cross.a_p.0,
            cal.orientation.cross.a_o.0,
        );
    }
    Ok(())
}
