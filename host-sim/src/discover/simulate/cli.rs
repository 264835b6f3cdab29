//! `accomp discover <record> --simulate [--scenario base.toml] [--ensemble N]
//! [--write-scenario out.toml]`: prints what the simulation gets wrong first, then the catalogue
//! search on the measured − twin residual.

use super::{output, Simulation};
use crate::discover::import::{self, DatasetOptions};
use crate::discover::{report, select, DiscoverArgs};
use std::fmt::Write as _;
use std::path::Path;

/// Loads the record as the discovery does (same binning and notes).
pub fn load(args: &DiscoverArgs) -> anyhow::Result<import::Dataset> {
    let (log, bad) = import::load_for_dataset(&args.log, args.format, args.output.as_deref())?;
    let opts = DatasetOptions {
        output: args.output.clone(),
        max_points: args.max_points,
        unit_per_g_from_calibration: None,
    };
    let mut ds = import::dataset_from_log(&log, &opts)?;
    crate::discover::note_bad_rows(&mut ds, &bad);
    Ok(ds)
}

/// Runs the comparison on a loaded record (library entry point of the CLI and the tests).
pub fn simulate_dataset(
    ds: &import::Dataset,
    scenario: Option<&Path>,
    ensemble: usize,
    cfg: &select::Config,
) -> anyhow::Result<Simulation> {
    let base = match scenario {
        Some(p) => Some(
            crate::sim::scenario::load(&p.to_string_lossy())
                .map_err(|e| anyhow::anyhow!("--scenario {}: {e}", p.display()))?,
        ),
        None => None,
    };
    let label = match scenario {
        Some(p) => p.display().to_string(),
        None => {
            "derived from the record (docs/simulator.md, \"Twin of a measured record\")".to_owned()
        }
    };
    super::simulate(
        ds,
        |noise| crate::sim::twin::Twin::new(ds, base.clone(), noise).map_err(|e| e.to_string()),
        label,
        ensemble,
        cfg,
    )
    .map_err(anyhow::Error::msg)
}

/// Writes the extended scenario, if asked.
pub fn write_scenario(s: &mut Simulation, path: Option<&Path>) -> anyhow::Result<()> {
    let Some(path) = path else {
        return Ok(());
    };
    let Some(toml) = &s.extended_toml else {
        anyhow::bail!(
            "--write-scenario {}: this twin has no scenario to write ({})",
            path.display(),
            s.warnings.join("; ")
        );
    };
    std::fs::write(path, toml)?;
    s.extended_path = Some(path.to_path_buf());
    Ok(())
}

/// Writes the discovery's report plus the simulation's section and figures.
pub fn write_report(s: &Simulation, dir: &Path, format: crate::plot::Format) -> anyhow::Result<()> {
    report::write_report(&s.cause, dir, format)?;
    let unit = s.cause.dataset.output_unit.clone();
    let mut md = String::new();
    let _ = writeln!(
        md,
        "\n# Simulation in the loop\n\n```text\n{}```\n",
        output::text(s, &unit)
    );
    for (stem, caption, fig) in output::figures(s, &unit) {
        let name = format!("{stem}.{}", format.ext());
        match crate::plot::draw::render(&fig, &dir.join(&name), format) {
            Ok(()) => {
                let _ = writeln!(md, "### {caption}\n\n![{caption}]({name})\n");
            }
            Err(e) => {
                let _ = writeln!(md, "### {caption}\n\nnot drawn: {e}\n");
            }
        }
    }
    let path = dir.join("report.md");
    let mut all = std::fs::read_to_string(&path).unwrap_or_default();
    all.push_str(&md);
    std::fs::write(path, all)?;
    Ok(())
}

/// `accomp discover --simulate`.
pub fn run(args: &DiscoverArgs) -> anyhow::Result<()> {
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
        args.ensemble,
        &select::Config::default(),
    )?;
    write_scenario(&mut s, args.write_scenario.as_deref())?;
    if let Some(dir) = &args.report {
        write_report(&s, dir, args.report_format)?;
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
