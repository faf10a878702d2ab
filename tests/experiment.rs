//! `presrs experiment all --quick`: every table and figure is written and is what it says.

mod common;

use std::process::Command;

#[test]
fn experiment_all_quick_writes_every_table_and_figure() {
    let dir = std::env::temp_dir().join(format!("presrs-exp-test-{}", std::process::id()));
    let _ = std::fs::remove_dir_all(&dir);
    common::output_ok(
        Command::new(env!("CARGO_BIN_EXE_presrs"))
            .args(["experiment", "all", "--quick", "--out"])
            .arg(&dir)
            .env("XDG_CACHE_HOME", dir.join("cache")),
    );
    let md = std::fs::read_to_string(dir.join("results.md")).unwrap();
    for heading in [
        "## Table 1",
        "## Resolution",
        "## Figure 13",
        "## Table 5",
        "## Table 3",
        "## Figure 16",
        "## Table 6",
        "## Gait adaptation",
    ] {
        assert!(md.contains(heading), "results.md lacks {heading}");
    }
    assert!(
        md.contains("simulat"),
        "results.md must say the data are simulated"
    );
    for fig in [
        "fig05-static-features.png",
        "resolution.png",
        "fig13-dynamic-features.png",
        "fig16-damage.png",
        "adaptation.png",
    ] {
        assert!(
            md.contains(&format!("figures/{fig}")),
            "results.md does not show {fig}"
        );
        let bytes = std::fs::read(dir.join("figures").join(fig)).unwrap();
        assert_eq!(&bytes[1..4], b"PNG", "{fig} is not a PNG");
        // A drawn figure, not an empty canvas: a blank PNG of this size compresses to ~10 KB.
        assert!(bytes.len() > 20_000, "{fig}: {} bytes", bytes.len());
    }
    // Table 1's diagonal is a percentage; the static set is classified far above chance.
    let overall = md
        .split("Overall accuracy: **")
        .nth(1)
        .and_then(|s| s.split('%').next())
        .and_then(|s| s.parse::<f64>().ok())
        .unwrap();
    assert!(overall > 90.0, "static accuracy {overall}");
    let _ = std::fs::remove_dir_all(&dir);
}
