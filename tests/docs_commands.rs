//! The commands the README and docs/ print are the commands that work: every `presrs` line of
//! their shell blocks names a subcommand and options that exist, and the README's path for a
//! lab's own robot (capture, train, replay, MCAP, the view) runs as written, on logs the
//! simulator writes in place of the robot's candump logs.

mod common;

use std::path::{Path, PathBuf};
use std::process::Command;

fn presrs() -> Command {
    Command::new(env!("CARGO_BIN_EXE_presrs"))
}

/// Every line of the ```sh and ```bash blocks of `text`, comments cut, `\` continuations joined.
fn shell_lines(text: &str) -> Vec<String> {
    let mut out = Vec::new();
    let mut in_block = false;
    let mut pending = String::new();
    for line in text.lines() {
        let t = line.trim();
        if t.starts_with("```") {
            in_block = !in_block && (t == "```sh" || t == "```bash");
            continue;
        }
        if !in_block {
            continue;
        }
        let code = match t.find(" #") {
            Some(i) => &t[..i],
            None if t.starts_with('#') => "",
            None => t,
        };
        if let Some(head) = code.strip_suffix('\\') {
            pending.push_str(head);
            pending.push(' ');
            continue;
        }
        pending.push_str(code);
        let whole = std::mem::take(&mut pending);
        if !whole.trim().is_empty() {
            out.push(whole.trim().to_string());
        }
    }
    out
}

/// The `presrs` commands of a shell line (split at `&&`, `;` and `|`), each as its arguments
/// after `presrs`, with redirections and a trailing `&` left out.
fn presrs_commands(line: &str) -> Vec<Vec<String>> {
    line.split("&&")
        .flat_map(|p| p.split(';'))
        .flat_map(|p| p.split('|'))
        .filter_map(|part| {
            let mut words = part.split_whitespace();
            (words.next()? == "presrs").then(|| {
                let mut args = Vec::new();
                let mut skip_next = false;
                for w in words {
                    if std::mem::take(&mut skip_next) || w == "&" {
                        continue;
                    }
                    if w == ">" || w == "2>" {
                        skip_next = true;
                        continue;
                    }
                    args.push(w.to_string());
                }
                args
            })
        })
        .collect()
}

fn doc_files() -> Vec<PathBuf> {
    let root = common::root();
    let mut files = vec![root.join("README.md")];
    let mut docs: Vec<PathBuf> = std::fs::read_dir(root.join("docs"))
        .unwrap()
        .map(|e| e.unwrap().path())
        .filter(|p| p.extension().is_some_and(|e| e == "md"))
        .collect();
    docs.sort();
    files.extend(docs);
    files
}

#[test]
fn the_shell_blocks_are_read_as_a_shell_would() {
    let text = "x\n```sh\npresrs a --b c   # a comment\n# only a comment\npresrs d \\\n  --e f > out.txt &\n```\n```toml\npresrs = 1\n```\n";
    let lines = shell_lines(text);
    assert_eq!(lines, ["presrs a --b c", "presrs d  --e f > out.txt &"]);
    assert_eq!(presrs_commands(&lines[1]), [["d", "--e", "f"]]);
    assert_eq!(
        presrs_commands("presrs lab dataset x && presrs train --data x"),
        [vec!["lab", "dataset", "x"], vec!["train", "--data", "x"]]
    );
    assert!(presrs_commands("sudo ./vcan-setup.sh vcan0").is_empty());
}

/// Each command with `--help` added: clap refuses an unknown subcommand, an unknown option or a
/// value its parser rejects before it prints the help, so a command the docs misspell fails.
#[test]
fn every_presrs_command_in_the_readme_and_docs_exists_as_written() {
    let mut checked = 0;
    let mut failures = Vec::new();
    for file in doc_files() {
        let text = std::fs::read_to_string(&file).unwrap();
        for line in shell_lines(&text) {
            for args in presrs_commands(&line) {
                // Shell variables of a loop (`pp/$b.log`) stand for a file name.
                let args: Vec<String> = args.iter().map(|a| a.replace("$b", "b")).collect();
                let out = presrs()
                    .args(&args)
                    .arg("--help")
                    .current_dir(common::root())
                    .output()
                    .unwrap();
                checked += 1;
                if !out.status.success() {
                    failures.push(format!(
                        "{}: `presrs {}`: {}",
                        file.display(),
                        args.join(" "),
                        String::from_utf8_lossy(&out.stderr).trim()
                    ));
                }
            }
        }
    }
    assert!(checked >= 30, "only {checked} commands found in the docs");
    assert!(failures.is_empty(), "{}", failures.join("\n"));
}

fn run(dir: &Path, args: &[String]) -> std::process::Output {
    let mut cmd = presrs();
    cmd.args(args).current_dir(dir).env("HOME", dir);
    common::output_ok(&mut cmd)
}

fn words(v: &[&str]) -> Vec<String> {
    v.iter().map(|s| s.to_string()).collect()
}

/// The README's "Your own robot" and "Look at a run" blocks, run as written in a scratch folder:
/// the simulator writes the logs the robot's candump would (wood and grass, twice each, and a
/// mixed run), `capture`'s lines for wood are run again for grass, as the README says to.
#[test]
fn the_readme_path_for_a_labs_robot_runs_as_written() {
    let readme = std::fs::read_to_string(common::root().join("README.md")).unwrap();
    let commands: Vec<Vec<String>> = shell_lines(&readme)
        .iter()
        .flat_map(|l| presrs_commands(l))
        .collect();
    let find = |prefix: &[&str]| -> Vec<Vec<String>> {
        commands
            .iter()
            .filter(|c| c.len() >= prefix.len() && c[..prefix.len()] == words(prefix)[..])
            .filter(|c| !c.iter().any(|w| w == "--iface"))
            .cloned()
            .collect()
    };
    // The robot's path labels each log as one terrain (`--label`); the simulator's path
    // (`--labels`, the next test) has its own.
    let captures: Vec<Vec<String>> = find(&["capture", "--replay"])
        .into_iter()
        .filter(|c| c.iter().any(|w| w == "--label"))
        .collect();
    let train = find(&["train", "--data", "set"]);
    let replay = find(&["node", "--replay", "run.log"]);
    let mcap = find(&["mcap", "run.log"]);
    let view = find(&["view", "run.mcap"]);
    for (what, c) in [
        ("capture", &captures),
        ("train", &train),
        ("node --replay", &replay),
        ("mcap", &mcap),
        ("view", &view),
    ] {
        assert!(!c.is_empty(), "the README lost its `presrs {what}` line");
    }

    let dir = std::env::temp_dir().join(format!("presrs-readme-{}", std::process::id()));
    let _ = std::fs::remove_dir_all(&dir);
    std::fs::create_dir_all(&dir).unwrap();
    for (terrain, seeds) in [("wood", [31, 32]), ("grass", [33, 34])] {
        let track = dir.join(format!("{terrain}.toml"));
        std::fs::write(
            &track,
            format!("diameter_m = 2.8\n[[segments]]\nterrain = \"{terrain}\"\nlength_m = 8.8\n"),
        )
        .unwrap();
        for (i, seed) in seeds.iter().enumerate() {
            let log = format!("{terrain}{}.log", i + 1);
            let track = track.to_str().unwrap();
            run(
                &dir,
                &words(&[
                    "lab",
                    "sim",
                    "--log",
                    &log,
                    "--duration",
                    "10",
                    "--track",
                    track,
                ])
                .into_iter()
                .chain(["--seed".to_string(), seed.to_string()])
                .collect::<Vec<_>>(),
            );
        }
    }
    run(
        &dir,
        &words(&[
            "lab",
            "sim",
            "--log",
            "run.log",
            "--duration",
            "8",
            "--seed",
            "35",
        ]),
    );
    for c in &captures {
        run(&dir, c);
        let grass: Vec<String> = c.iter().map(|w| w.replace("wood", "grass")).collect();
        run(&dir, &grass);
    }
    for c in train.iter().chain(&replay).chain(&mcap).chain(&view) {
        run(&dir, c);
    }
    for made in [
        "set/manifest.csv",
        "model.json",
        "run.mcap",
        "view.png",
        "steps.csv",
    ] {
        let len = std::fs::metadata(dir.join(made))
            .map(|m| m.len())
            .unwrap_or(0);
        assert!(len > 0, "`{made}` was not written");
    }
    let _ = std::fs::remove_dir_all(&dir);
}

/// The README's "Try it on the simulator" path to a model of one's own and the new ground it
/// meets, run as written in a scratch folder: a recorded session, its stances, `train`, a run
/// on sand, the node's keep of it and `discover`.
#[test]
fn the_readme_path_on_the_simulator_runs_as_written() {
    let root = common::root();
    let readme = std::fs::read_to_string(root.join("README.md")).unwrap();
    let commands: Vec<Vec<String>> = shell_lines(&readme)
        .iter()
        .flat_map(|l| presrs_commands(l))
        // Paths in the repository, from the scratch folder.
        .map(|c| {
            c.into_iter()
                .map(|w| match w.strip_prefix("examples/") {
                    Some(f) => root.join("examples").join(f).display().to_string(),
                    None => w,
                })
                .collect()
        })
        .collect();
    let has = |c: &[String], w: &str| c.iter().any(|x| x == w);
    let path: Vec<&Vec<String>> = commands
        .iter()
        .filter(|c| {
            (c[0] == "demo" && has(c, "--candump") && has(c, "--truth"))
                || (c[0] == "capture" && has(c, "--labels"))
                || (c[0] == "node"
                    && has(c, "--keep-unknown")
                    && has(c, "--replay")
                    && has(c, "--truth"))
                || c[0] == "discover" && !has(c, "--add")
        })
        .collect();
    let kinds: Vec<&str> = path.iter().map(|c| c[0].as_str()).collect();
    assert_eq!(
        kinds,
        ["demo", "capture", "demo", "node", "discover"],
        "the README's simulator path changed: {path:?}"
    );
    let dir = std::env::temp_dir().join(format!("presrs-readme-sim-{}", std::process::id()));
    let _ = std::fs::remove_dir_all(&dir);
    std::fs::create_dir_all(&dir).unwrap();
    let train = words(&["train", "--data", "set", "--out", "model.json"]);
    for c in &path[..2] {
        run(&dir, c);
    }
    run(&dir, &train);
    run(&dir, path[2]);
    // The replay held against the truth: sand, which the model never saw, is new ground.
    let said = String::from_utf8_lossy(&run(&dir, path[3]).stderr).to_string();
    assert!(
        said.contains("known ground called unknown (the safe gait): ")
            && said.contains("new ground found: ")
            && said
                .lines()
                .any(|l| l.trim_start().starts_with("sand ") && l.contains(" new ")),
        "{said}"
    );
    let out = run(&dir, path[4]);
    let table = String::from_utf8_lossy(&out.stdout);
    assert!(
        table.contains("unknown stances kept in kept") && table.contains("kept for"),
        "{table}"
    );
    let _ = std::fs::remove_dir_all(&dir);
}
