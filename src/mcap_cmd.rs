//! `presrs mcap` (a candump log to an MCAP file or a ROS 2 bag) and `presrs view` (a recording
//! as one PNG). The channels and the writing are [`record`]'s and [`ros2`]'s, the picture
//! [`tools::view`]'s; this module reads arguments and says what happened.

use std::process::ExitCode;

use anyhow::{Context, Result};
use node::NodeService;
use node::classifier::Model;
use presrs_cli::mcap::{McapArgs, ViewArgs};
use record::{McapFile, Recorder, Sink};

pub fn run(a: McapArgs) -> Result<ExitCode> {
    let mut cfg =
        node::NodeConfig::load_or_default(a.config.as_deref(), &a.terrains).context("--config")?;
    let catalog = cfg.catalog().context("--config terrains")?;
    let ids = cfg.ids.clone();
    let mut node = match &a.model {
        Some(m) => {
            let model = Model::load(m).context("--model")?;
            // The same decisions on every conversion, as `presrs node --replay` makes them.
            cfg.refit = cfg.refit.reproducible();
            Some(NodeService::new(cfg, model).with_context(|| format!("--model {}", m.display()))?)
        }
        None => None,
    };
    // Checked to its end before the recording is created, then streamed.
    let file = protocol::candump::LogFile::check(&a.log)?;
    let mut records = file.records()?;
    if a.ros2 {
        let names = ros2::Names::new(0, &a.namespace)?;
        let mut bag = ros2::RosBag::create(&a.out, names.clone()).context("--out")?;
        let mut enc = ros2::Encoder::new(ids, catalog, &names);
        tools::replay::log_to_bag(&mut records, node.as_mut(), &mut enc, &mut bag)
            .context("--out")?;
        bag.finish().context("--out")?;
        records.finish()?;
        let s = enc.stats();
        if a.json {
            println!(
                "{}",
                serde_json::json!({ "frames": file.records, "out": a.out,
                    "messages": s.messages, "undecodable": s.undecodable, "foreign": s.foreign })
            );
        }
        eprintln!(
            "{} frames -> {} (rosbag2): {} messages; {} undecodable and {} foreign frames left out",
            file.records,
            a.out.display(),
            s.messages,
            s.undecodable,
            s.foreign
        );
        return Ok(ExitCode::SUCCESS);
    }
    let mut out = McapFile::create(&a.out).context("--out")?;
    let mut rec = Recorder::new(ids, catalog);
    tools::replay::log_to_recording(&mut records, node.as_mut(), &mut rec, &mut out)
        .context("--out")?;
    records.finish()?;
    out.finish().context("--out")?;
    let s = rec.stats();
    if a.json {
        println!(
            "{}",
            serde_json::json!({ "frames": file.records, "out": a.out, "stats": s })
        );
    }
    eprintln!("{} frames -> {}: {s}", file.records, a.out.display());
    Ok(ExitCode::SUCCESS)
}

/// `presrs view`: a recording's pressure image beside a panel per kind of data it holds.
pub fn view(a: ViewArgs) -> Result<ExitCode> {
    let msgs = record::read::read_json(&a.recording)?;
    anyhow::ensure!(
        !msgs.is_empty(),
        "{}: no JSON messages (is it a presrs recording?)",
        a.recording.display()
    );
    let name = a
        .recording
        .file_name()
        .map_or_else(String::new, |n| n.to_string_lossy().to_string());
    let s = tools::view::render(
        &msgs,
        a.foot,
        a.at,
        &format!("{name}, foot {}", a.foot),
        &a.out,
    )
    .with_context(|| format!("--out {}", a.out.display()))?;
    eprintln!("{}: {s} -> {}", a.recording.display(), a.out.display());
    Ok(ExitCode::SUCCESS)
}
