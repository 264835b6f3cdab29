//! `accomp demo` (run by `cargo xtask demo`): the flags and the printed report (the demo itself
//! is [`crate::demo`]).

use crate::demo::run_demo;

/// Arguments of `accomp demo`: the demo's own options, one struct (see [`crate::demo`]).
pub use crate::demo::DemoOptions as DemoArgs;

/// `accomp demo`.
pub fn run(args: &DemoArgs) -> anyhow::Result<()> {
    let report = run_demo(args)?;
    print!("{}", report.to_text());
    println!(
        "report: {} and {}",
        args.out_dir.join("report.txt").display(),
        args.out_dir.join("report.json").display()
    );
    Ok(())
}
