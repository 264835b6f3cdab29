//! The command line's glue, one file per subcommand of `accomp` (`main.rs` only dispatches): its
//! clap arguments, reading the files it names, calling the domain module, printing and writing
//! what it returns. The domain modules (`fit`, `sim`, `tumble`, `discover`, `plot`, `stability`,
//! `device`) hold no clap: the domain's value enums (`plot::Format`, `plot::Kind`,
//! `discover::import::Format`) get their command-line names in [`values`]. Two option structs are
//! a command's flags one for one and derive them where they are defined, so each option is
//! written and documented once: `demo::DemoOptions` (`accomp demo`) and
//! `device::record::Options` (`accomp record`, behind accomp-device's `clap` feature).

pub mod board_sim;
pub mod compensate;
pub mod demo;
pub mod device;
pub mod discover;
pub mod fit;
pub mod load;
pub mod plot;
pub mod record;
pub mod record_tui;
pub mod simulate;
pub mod simulate_tumble;
pub mod stability;
pub mod table;
pub mod tumble;
pub mod values;

/// `--allow-large` of the commands that read a log.
#[derive(Debug, Clone, clap::Args)]
pub struct LogLimitArgs {
    /// Read a log above the reader's limits (20 million data lines, 4 GiB).
    #[arg(long)]
    pub allow_large: bool,
}

impl LogLimitArgs {
    /// Lifts the log reader's size limits for this run when `--allow-large` is given.
    pub fn apply(&self) {
        crate::log::reader::set_allow_large(self.allow_large);
    }
}
