//! `presrs capture`: a training set from the robot's own runs. The work is
//! [`node::capture`]; this module reads the arguments, the log or the bus, and prints the summary.

use std::process::ExitCode;
use std::time::Duration;

use anyhow::{Context, Result, bail};
use node::capture::{Capture, CaptureService, CaptureSet, Labelling};
use presrs_cli::capture::CaptureArgs;
use protocol::bus::{BusSource, CanBus};
use protocol::component::{self, RunOptions};

use protocol::component::Signals;

pub fn run(a: CaptureArgs) -> Result<ExitCode> {
    let cfg =
        node::NodeConfig::load_or_default(a.config.as_deref(), &a.terrains).context("--config")?;
    let catalog = cfg.catalog()?;
    let labelling = Labelling::from_args(a.label.as_deref(), a.labels.as_deref(), &catalog)?;
    // A log is checked to its end before the set is opened: a bad line fails the capture with
    // nothing created, and the records then stream (a long log is not held in memory).
    let log = a
        .replay
        .as_deref()
        .map(protocol::candump::LogFile::check)
        .transpose()?;
    let mut service = CaptureService::new(
        Capture::new(cfg, labelling),
        CaptureSet::open(&a.out)?,
        String::new(),
    );
    if let Some(file) = &log {
        service.source = a.source.clone().unwrap_or_else(|| {
            file.path()
                .file_name()
                .map_or("log".into(), |n| n.to_string_lossy().to_string())
        });
        let mut records = file.records()?;
        service.replay(&mut records);
        records.finish()?;
    } else if let Some(iface) = &a.iface {
        let signals = Signals::install()?;
        let start = std::time::SystemTime::now()
            .duration_since(std::time::UNIX_EPOCH)
            .map_or(0, |d| d.as_secs());
        service.source = a
            .source
            .clone()
            .unwrap_or_else(|| format!("{iface}-{start}"));
        // A wrong name fails here at once; an interface that goes down later is reopened
        // with the backoff every bus loop uses (images written so far stay written).
        let bus: Box<dyn CanBus> = Box::new(protocol::bus::SocketCanBus::open(iface)?);
        tracing::info!(%iface, out = %a.out.display(), "capturing until SIGINT/SIGTERM");
        let opts = RunOptions {
            tick: Duration::from_millis(50),
            ..RunOptions::default()
        };
        let source = BusSource::Iface(iface.clone());
        component::run_opened(&mut service, Some(bus), &source, &opts, &signals.stop);
    } else {
        bail!("give --replay FILE.log or --iface IFACE");
    }
    if a.json {
        println!("{}", service.report_json(&a.out));
    } else {
        eprintln!("{}", service.report(&a.out));
    }
    let (failed, written) = (service.failed, service.set.written);
    if let Some(e) = failed {
        return Err(e).context(format!("capture stopped after {written} images"));
    }
    Ok(ExitCode::SUCCESS)
}
