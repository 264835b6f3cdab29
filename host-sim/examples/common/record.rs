//! The measured record an example reads: its first argument, else the gMetrology relative
//! gravimeter record of data/measured (`#[path = "common/record.rs"] mod record;`).

/// The record's path: `args[1]`, else the gMetrology record.
pub fn path_arg(args: &[String]) -> String {
    args.get(1).cloned().unwrap_or_else(|| {
        concat!(
            env!("CARGO_MANIFEST_DIR"),
            "/../data/measured/gmetrology_relative_gravimeter_2021-06-08_51d.tsf"
        )
        .to_owned()
    })
}
