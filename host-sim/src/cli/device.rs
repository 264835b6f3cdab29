//! `accomp device info|ping|rollback|activate|set-rate`: one command per request of the protocol
//! that has no workflow command of its own (`load` uploads, `record` streams).

use std::path::PathBuf;

use accomp::protocol::{BootReport, DeviceInfo, Request, Response};

use crate::device::{Connection, Target};

/// `accomp device`: talk to the board one request at a time.
#[derive(clap::Args, Debug)]
pub struct DeviceArgs {
    /// What to ask.
    #[command(subcommand)]
    pub action: Action,
    /// qemu or serial:<port>
    #[arg(long, global = true)]
    pub target: Option<Target>,
    /// Print one JSON object instead of text.
    #[arg(long, global = true)]
    pub json: bool,
    /// Firmware ELF for --target qemu.
    #[arg(long, global = true)]
    pub firmware: Option<PathBuf>,
}

/// The requests.
#[derive(clap::Subcommand, Debug, Clone)]
pub enum Action {
    /// Firmware and protocol versions, board, uptime, reset reason, tables, rate, counters.
    Info,
    /// Liveness check (prints the round-trip time).
    Ping,
    /// Swap the active and the previous table.
    Rollback,
    /// Make the table with this id (hex, as `info` prints it) active: the active or previous one.
    Activate {
        /// Table id, e.g. 0x1a2b3c4d.
        id: String,
    },
    /// Set the ADS1262 data rate (samples per second; frames come at rate / 8).
    SetRate {
        /// One of 5, 10, 20, 50, 60, 100, 400.
        hz: u32,
    },
}

/// Runs `accomp device …`.
pub fn run(args: &DeviceArgs) -> anyhow::Result<()> {
    let target = args
        .target
        .clone()
        .ok_or_else(|| anyhow::anyhow!("--target qemu|serial:<port> is required"))?;
    let mut conn = Connection::open(&target, args.firmware.as_deref())?;
    let c = &mut conn.client;
    match &args.action {
        Action::Info => {
            let info = c.info()?;
            if args.json {
                println!("{}", info_json(&info));
            } else {
                print!("{}", info_text(&info));
            }
        }
        Action::Ping => {
            let t = std::time::Instant::now();
            c.ping()?;
            let ms = t.elapsed().as_secs_f64() * 1e3;
            if args.json {
                println!(
                    "{}",
                    serde_json::json!({ "pong": true, "round_trip_ms": ms })
                );
            } else {
                println!("pong in {ms:.1} ms");
            }
        }
        Action::Rollback => {
            expect_ok(c.call(Request::Rollback)?)?;
            report_tables(c, args.json, "rolled back")?;
        }
        Action::Activate { id } => {
            let table_id = parse_table_id(id)?;
            expect_ok(c.call(Request::Activate { table_id })?)?;
            report_tables(c, args.json, "activated")?;
        }
        Action::SetRate { hz } => {
            expect_ok(c.call(Request::SetRate { hz: *hz })?)?;
            if args.json {
                println!("{}", serde_json::json!({ "rate_hz": hz }));
            } else {
                println!("rate {hz} samples/s");
            }
        }
    }
    Ok(())
}

fn expect_ok(r: Response) -> anyhow::Result<()> {
    match r {
        Response::Ok => Ok(()),
        other => anyhow::bail!("unexpected answer {other:?}"),
    }
}

fn report_tables(c: &mut crate::device::Client, json: bool, what: &str) -> anyhow::Result<()> {
    let info = c.info()?;
    if json {
        println!(
            "{}",
            serde_json::json!({
                "active_table": info.active_table.map(table_id_text),
                "previous_table": info.previous_table.map(table_id_text),
            })
        );
    } else {
        println!(
            "{what}: active {}, previous {}",
            opt_id(info.active_table),
            opt_id(info.previous_table)
        );
    }
    Ok(())
}

/// A table id as typed on the command line: hex with or without `0x`.
pub fn parse_table_id(s: &str) -> anyhow::Result<u32> {
    let hex = s
        .strip_prefix("0x")
        .or_else(|| s.strip_prefix("0X"))
        .unwrap_or(s);
    u32::from_str_radix(hex, 16)
        .map_err(|_| anyhow::anyhow!("table id {s:?} is not a hexadecimal number like 0x1a2b3c4d"))
}

/// A table id as `info` prints it.
pub fn table_id_text(id: u32) -> String {
    format!("{id:#010x}")
}

fn opt_id(id: Option<u32>) -> String {
    id.map_or_else(|| "none".into(), table_id_text)
}

/// The reset causes set in `reset_cause`, by name (RCC_CSR bits, see [`BootReport`]).
pub fn reset_causes(boot: &BootReport) -> Vec<&'static str> {
    const NAMES: [(u8, &str); 7] = [
        (BootReport::BOR, "brown-out"),
        (BootReport::PIN, "reset pin"),
        (BootReport::POR, "power-on"),
        (BootReport::SOFTWARE, "software"),
        (BootReport::IWDG, "independent watchdog"),
        (BootReport::WWDG, "window watchdog"),
        (BootReport::LOW_POWER, "low-power"),
    ];
    NAMES
        .iter()
        .filter(|(bit, _)| boot.reset_cause & bit != 0)
        .map(|(_, n)| *n)
        .collect()
}

/// Info as one JSON object (every field, ids in hex).
pub fn info_json(i: &DeviceInfo) -> serde_json::Value {
    serde_json::json!({
        "firmware": i.firmware.as_str(),
        "protocol": i.protocol,
        "board": format!("{:?}", i.board),
        "uptime_us": i.uptime_us,
        "reset_cause": i.boot.reset_cause,
        "reset_causes": reset_causes(&i.boot),
        "clock_fallback": i.boot.clock_fallback,
        "boot_id": format!("{:#010x}", i.boot.boot_id),
        "active_table": i.active_table.map(table_id_text),
        "previous_table": i.previous_table.map(table_id_text),
        "rate_hz": i.rate_hz,
        "streaming": i.streaming,
        "samples": i.samples,
        "frames_dropped": i.frames_dropped,
        "losses": crate::device::record::counter_values(i)
            .into_iter()
            .skip(1)
            .collect::<std::collections::BTreeMap<_, _>>(),
    })
}

/// Info as aligned text lines.
pub fn info_text(i: &DeviceInfo) -> String {
    let causes = reset_causes(&i.boot);
    let cause = if causes.is_empty() {
        "unknown".to_string()
    } else {
        causes.join(", ")
    };
    format!(
        "firmware        {}\nprotocol        {}\nboard           {:?}\nuptime          {:.3} s\n\
         reset cause     {cause} ({:#04x}){}\nboot id         {:#010x}\nactive table    {}\nprevious table  {}\n\
         rate            {} samples/s\nstreaming       {}\nsamples         {}\n\
         frames dropped  {}\n{}",
        i.firmware,
        i.protocol,
        i.board,
        i.uptime_us as f64 / 1e6,
        i.boot.reset_cause,
        if i.boot.clock_fallback {
            ", clock on HSI fallback"
        } else {
            ""
        },
        i.boot.boot_id,
        opt_id(i.active_table),
        opt_id(i.previous_table),
        i.rate_hz,
        i.streaming,
        i.samples,
        i.frames_dropped,
        crate::device::record::counter_values(i)
            .into_iter()
            .skip(1)
            .map(|(k, v)| format!("{:<16}{v}\n", k.replace('_', " ")))
            .collect::<String>(),
    )
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn table_ids_parse_with_or_without_prefix_and_refuse_non_hex() {
        assert_eq!(parse_table_id("0x1A2b3c4d").unwrap(), 0x1a2b_3c4d);
        assert_eq!(parse_table_id("ff").unwrap(), 0xff);
        assert!(parse_table_id("0xg1").is_err());
        assert_eq!(table_id_text(0xff), "0x000000ff");
    }

    #[test]
    fn reset_causes_are_named_bit_by_bit() {
        let b = BootReport {
            reset_cause: BootReport::PIN | BootReport::IWDG,
            ..BootReport::default()
        };
        assert_eq!(reset_causes(&b), vec!["reset pin", "independent watchdog"]);
    }
}
