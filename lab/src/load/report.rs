//! The bench's report: latency, CPU and memory, as text and `--json`.

use super::{FRAME_US, SIDE, Tally, Variant};

/// `presrs lab bench-node`'s report of one measurement.
pub struct BenchReport<'a> {
    /// The bus measured on ("inproc", "vcan0").
    pub bus: &'a str,
    /// A label carried into the report ("emulated").
    pub label: Option<&'a str>,
    /// Feet played.
    pub feet: u8,
    /// Measured seconds.
    pub seconds: f64,
    /// What the memory figures cover.
    pub memory_scope: &'a str,
    /// What [`measure`] counted.
    pub tally: &'a Tally,
    /// Resident and peak resident memory, MB ([`memory_mb`]).
    pub memory_mb: (Option<f64>, Option<f64>),
    /// Figures of the bus or the recorder, as they are.
    pub extra: serde_json::Value,
}

impl BenchReport<'_> {
    fn latencies(&self) -> Vec<f64> {
        let mut lat = self.tally.latencies_us.clone();
        lat.sort_by(f64::total_cmp);
        lat
    }

    fn cpu_pct(&self) -> Option<f64> {
        self.tally
            .cpu_ns
            .map(|ns| ns as f64 * 1e-9 / self.seconds * 100.0)
    }

    fn accuracy(&self) -> f64 {
        let t = self.tally;
        if t.classified > 0 {
            t.correct as f64 / t.classified as f64
        } else {
            0.0
        }
    }

    /// The node's CPU per 1,000 CAN frames, µs: what a lab scales to its own bus and board.
    fn cpu_us_per_1000_frames(&self) -> Option<f64> {
        let frames = self.frames_per_s() * self.seconds;
        self.tally
            .cpu_ns
            .filter(|_| frames > 0.0)
            .map(|ns| ns as f64 * 1e-3 / (frames / 1000.0))
    }

    fn frames_per_s(&self) -> f64 {
        self.feet as f64
            * (1e6 / FRAME_US as f64)
            * Variant::Fd.frames_per_image(SIDE, SIDE, 8) as f64
    }

    /// `--json`'s object.
    pub fn to_json(&self) -> serde_json::Value {
        use tools::eval::percentile;
        let (t, lat) = (self.tally, self.latencies());
        let mut bus = t.bus_latencies_us.clone();
        bus.sort_by(f64::total_cmp);
        serde_json::json!({
            "bus": self.bus,
            "label": self.label,
            "feet": self.feet,
            "seconds": self.seconds,
            "tactile_hz_per_foot": 1e6 / FRAME_US as f64,
            "can_frames_per_s": self.frames_per_s(),
            "steps": t.steps,
            "load_send_errors": t.send_errors,
            "terrain_class": t.decisions,
            "terrain_class_heard_before_logged": t.heard_before_logged,
            "node_status_last": t.node_status.map(|n| serde_json::json!({
                "crc_failures": n.crc_failures,
                "incomplete_frames": n.incomplete_frames,
                "bus_errors": n.bus_errors,
            })),
            "classified": t.classified,
            "accuracy": self.accuracy(),
            "latency_us": {
                "what": "last segment of the sampled frame sent -> TerrainClass received",
                "n": lat.len(),
                "median": percentile(&lat, 0.5),
                "p99": percentile(&lat, 0.99),
                "max": lat.last(),
            },
            "latency_on_bus_us": {
                "what": "the same, on the bus's clock: last segment sent -> the TerrainClass's \
                         receive stamp (without the listener's wake-up)",
                "n": bus.len(),
                "median": percentile(&bus, 0.5),
                "p99": percentile(&bus, 0.99),
                "max": bus.last(),
            },
            "node_cpu_pct_of_one_core": self.cpu_pct(),
            "node_cpu_us_per_1000_frames": self.cpu_us_per_1000_frames(),
            "rss_mb": self.memory_mb.0,
            "peak_rss_mb": self.memory_mb.1,
            "memory_scope": self.memory_scope,
            "extra": self.extra,
        })
    }
}

impl std::fmt::Display for BenchReport<'_> {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        use tools::eval::percentile;
        let (t, lat) = (self.tally, self.latencies());
        let n = |v: Option<f64>| v.map_or("n/a".to_string(), |v| format!("{v:.1}"));
        writeln!(
            f,
            "bus {}{}: {} feet at 100 Hz for {} s ({:.0} CAN FD frames/s)",
            self.bus,
            self.label.map(|l| format!(" ({l})")).unwrap_or_default(),
            self.feet,
            self.seconds,
            self.frames_per_s()
        )?;
        writeln!(
            f,
            "steps {}, TerrainClass {}, classified {}, correct {:.1}%",
            t.steps,
            t.decisions,
            t.classified,
            self.accuracy() * 100.0
        )?;
        writeln!(
            f,
            "latency (sampled frame's last segment -> TerrainClass): median {} us, p99 {} us, max {} us",
            n(percentile(&lat, 0.5)),
            n(percentile(&lat, 0.99)),
            n(lat.last().copied())
        )?;
        writeln!(
            f,
            "node CPU {}% of one core ({} us per 1,000 frames); memory ({}) {} MB, peak {} MB",
            n(self.cpu_pct()),
            n(self.cpu_us_per_1000_frames()),
            self.memory_scope,
            n(self.memory_mb.0),
            n(self.memory_mb.1)
        )?;
        if let Some(b) = self.extra.get("beside").filter(|b| !b.is_null()) {
            writeln!(
                f,
                "ROS 2 bridge beside it: CPU {:.1}% of one core, {} frames dropped",
                b["cpu_pct_of_one_core"].as_f64().unwrap_or(f64::NAN),
                b["dropped"]
            )?;
        }
        if let Some(k) = self.extra.get("kept_unknown").filter(|k| !k.is_null()) {
            writeln!(
                f,
                "kept {} unknown stances, {} dropped",
                k["written"], k["dropped"]
            )?;
        }
        Ok(())
    }
}
