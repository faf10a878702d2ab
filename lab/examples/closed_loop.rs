//! The whole loop in one process: the simulated hopper on the paper's course, the terrain node
//! and the gait controller on one in-process bus, in lock-step simulated time.
//!
//! ```text
//! cargo run --release -p presrs-lab --example closed_loop -- 60
//! ```
//!
//! The model is the one `presrs demo` uses: trained on simulated stances of the three gaits on
//! first use, then cached. Each decided step prints with the truth beside it.

use controller::ControllerConfig;
use presrs_lab::closed_loop::{self, LoopParams};
use presrs_lab::model::load_or_train;
use sim::runner::Track;

fn main() -> Result<(), Box<dyn std::error::Error>> {
    let steps = std::env::args()
        .nth(1)
        .map(|s| s.parse())
        .transpose()?
        .unwrap_or(60);
    let (model, _) = load_or_train(None, || eprintln!("training the simulator model..."))?;
    let controller = ControllerConfig::default();
    let params = LoopParams::with_controller(&controller, steps, 1);
    let run = closed_loop::run(&Track::default(), model, &params, |row| {
        println!(
            "{:7.2} s  {:>14} said {:<14} gait G{}",
            row.t_s, row.truth, row.classified, row.gait
        );
    })?;
    let right = run.rows.iter().filter(|r| r.is_correct()).count();
    println!(
        "{right}/{} steps right, {} falls",
        run.rows.len(),
        run.falls()
    );
    Ok(())
}
