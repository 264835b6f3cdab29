//! report.txt: the experiments' figures beside the paper's.

use super::stream::STREAM_CHUNK;
use super::*;

/// Formats a stability in the unit the paper uses for the experiment (g for 1 g, µg for 0 g).
fn fmt_g(v: f64, micro: bool) -> String {
    if micro {
        format!("{:.2} µg", v * 1e6)
    } else {
        format!("{v:.2e} g")
    }
}

impl Report {
    /// The text printed at the end of the demo.
    pub fn to_text(&self) -> String {
        let mut s = String::new();
        s.push_str(&format!(
            "accomp demo — seed {}, firmware {}\n",
            self.seed,
            self.firmware.display()
        ));
        let orders: Vec<String> = self
            .fit_orders
            .iter()
            .map(|(n, o)| format!("{n} order {o}"))
            .collect();
        s.push_str(&format!(
            "Table 1 fit ({}): {} → {}\n",
            self.table1.display(),
            orders.join(", "),
            self.calibration.display()
        ));
        for e in &self.experiments {
            let micro = e.input_g.abs() < 0.5;
            s.push_str(&format!(
                "\n{} — {}, {:.0} g input, {} °C, {} days: {} samples every {} s (time-compressed {:.0}×: {:.1} s of streaming)\n",
                e.name,
                e.instrument,
                e.input_g,
                e.setpoint_c,
                e.duration_days,
                e.samples,
                e.interval_s,
                e.time_compression,
                e.stream_wall_s
            ));
            s.push_str(&format!(
                "  table {} uploaded and read back; firmware frames identical to the host core: {}\n",
                e.table_id,
                if e.host_mismatches == 0 {
                    "all".to_owned()
                } else {
                    format!("NO ({} differ)", e.host_mismatches)
                }
            ));
            if e.retried_chunks > 0 || e.device_frames_dropped > 0 || e.host_bad_frames > 0 {
                s.push_str(&format!(
                    "  link: {} chunk(s) of {STREAM_CHUNK} readings sent again, device dropped {} frame(s), host could not decode {}\n",
                    e.retried_chunks, e.device_frames_dropped, e.host_bad_frames
                ));
            }
            s.push_str(&format!(
                "  measured temperature std {:.4} °C, tilt peak-to-peak {:.2}\"\n",
                e.temperature_std_c, e.tilt_pp_arcsec
            ));
            s.push_str(&format!(
                "  {:<52} {:>12} {:>12}\n",
                "stability (std of equally spaced readings)", "this run", "paper"
            ));
            for f in &e.figures {
                s.push_str(&format!(
                    "  {:<52} {:>12} {:>12}\n",
                    f.label,
                    fmt_g(f.std_g, micro),
                    f.paper_g.map_or("–".into(), |p| fmt_g(p, micro))
                ));
            }
            for n in &e.notes {
                s.push_str(&format!("  note: {n}\n"));
            }
            if !e.status_counts.is_empty() {
                let c: Vec<String> = e
                    .status_counts
                    .iter()
                    .map(|(n, k)| format!("{n} ×{k}"))
                    .collect();
                s.push_str(&format!("  status flags: {}\n", c.join(", ")));
            }
            s.push_str(&format!("  log: {}\n", e.log.display()));
            if !e.plots.is_empty() {
                let p: Vec<String> = e.plots.iter().map(|p| p.display().to_string()).collect();
                s.push_str(&format!("  figures: {}\n", p.join(", ")));
            }
        }
        s.push_str(&format!("\ndemo wall time {:.1} s\n", self.wall_s));
        s
    }
}
