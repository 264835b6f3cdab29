//! Library entry points of `accomp discover <record> --simulate` (the command itself is
//! `accomp_host::cli::discover`): the comparison on a loaded record, the extended scenario and the
//! report's simulation section.

use super::{output, Simulation};
use crate::discover::{import, report, select, DiscoverError};
use std::fmt::Write as _;
use std::path::Path;

/// Runs the comparison on a loaded record (library entry point of the CLI and the tests).
pub fn simulate_dataset(
    ds: &import::Dataset,
    scenario: Option<&Path>,
    ensemble: usize,
    cfg: &select::Config,
) -> Result<Simulation, DiscoverError> {
    let base =
        match scenario {
            Some(p) => Some(crate::sim::scenario::load(&p.to_string_lossy()).map_err(
                |source| DiscoverError::Scenario {
                    path: p.to_path_buf(),
                    source,
                },
            )?),
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
        |noise| crate::twin::Twin::new(ds, base.clone(), noise),
        label,
        ensemble,
        cfg,
    )
    .map_err(DiscoverError::Simulate)
}

/// Writes the extended scenario, if asked. With a noise family it is the written twin: the
/// scenario with its `[twin]` section, and beside it the driver file `<stem>.drivers.csv`
/// (`accomp simulate FILE --seed k` then computes member k of the extended ensemble).
pub fn write_scenario(s: &mut Simulation, path: Option<&Path>) -> Result<(), DiscoverError> {
    let Some(path) = path else {
        return Ok(());
    };
    if let Some(m) = &s.written_twin {
        let stem = path
            .file_stem()
            .map_or_else(|| "twin".to_owned(), |x| x.to_string_lossy().into_owned());
        let drivers_name = format!("{stem}.drivers.csv");
        let ds = &s.cause.dataset;
        let (scenario, drivers) = m.written(&drivers_name, &ds.output_name, &ds.output_unit);
        crate::log::outputs::write_file(&path.with_file_name(&drivers_name), drivers.as_bytes())?;
        crate::log::outputs::write_file(path, scenario.to_toml().as_bytes())?;
        s.extended_path = Some(path.to_path_buf());
        return Ok(());
    }
    let Some(toml) = &s.extended_toml else {
        return Err(DiscoverError::NoScenario {
            path: path.to_path_buf(),
            why: s.warnings.join("; "),
        });
    };
    crate::log::outputs::write_file(path, toml.as_bytes())?;
    s.extended_path = Some(path.to_path_buf());
    Ok(())
}

/// Writes the discovery's report plus the simulation's section and figures.
pub fn write_report(
    s: &Simulation,
    dir: &Path,
    format: crate::plot::Format,
) -> Result<(), DiscoverError> {
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
    crate::log::outputs::write_file(&path, all.as_bytes())?;
    Ok(())
}
