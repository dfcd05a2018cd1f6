//! docs/getting-started.md runs as written: its project files are written and its commands run,
//! in page order, in a temporary directory, and each command's output must hold the lines the
//! page shows. The page cannot rot: a changed net, output or option fails this test.
//!
//! The page's convention (it says so at its end):
//! - a fenced block whose info string has `file=PATH` (```` ```toml file=patrol/petrel.toml ````)
//!   is a file, written to PATH (relative to the working directory) when the reader reaches it;
//! - a ```` ```sh ```` block holds commands: each line starting with `$ ` is one, run with `sh`
//!   in the working directory; the lines after it, up to the next `$ `, are what it prints
//!   (standard output and error together). Each shown line must be a line of the output, in
//!   order; a line `...` stands for any lines, and `...` inside a line for any text. A
//!   command exits 0, or the code a comment `# exit N` at its end says;
//! - other blocks (```` ```text ````, ```` ```rust ```` without `file=`) are only read.
//!
//! `petrel` is this build's (target/debug first in PATH). The generated program builds in
//! `target/prototypes`, shared with tests/tests/gen.rs (CARGO_TARGET_DIR), so that the SDK
//! and iceoryx2 are compiled once. The page's vehicle name, `patrol1`, is replaced by a name of
//! this run alone (iceoryx2 is per vehicle).

use petrel_tests::{forget_vehicle, petrel_bin, repo, unique_vehicle, Workdir};
use std::process::Command;

/// What the page asks: write a file, or run a command and find these lines in its output.
#[derive(Debug, PartialEq)]
enum Step {
    File {
        path: String,
        text: String,
    },
    Run {
        command: String,
        exit: i32,
        shown: Vec<String>,
    },
}

/// The steps of a page, in order (the convention above).
fn steps(page: &str) -> Vec<Step> {
    let mut out = Vec::new();
    let mut lines = page.lines();
    while let Some(line) = lines.next() {
        let Some(info) = line.strip_prefix("```") else {
            continue;
        };
        let body: Vec<&str> = lines
            .by_ref()
            .take_while(|l| !l.starts_with("```"))
            .collect();
        let file = info
            .split_whitespace()
            .find_map(|w| w.strip_prefix("file="));
        if let Some(path) = file {
            let mut text = body.join("\n");
            text.push('\n');
            out.push(Step::File {
                path: path.to_string(),
                text,
            });
        } else if info.trim() == "sh" {
            for l in body {
                if let Some(command) = l.strip_prefix("$ ") {
                    // `# exit N` at the end: the exit code the page says (a comment for sh).
                    let exit = command
                        .rsplit_once("# exit ")
                        .map(|(_, code)| code.trim().parse().expect("`# exit N`: a number"))
                        .unwrap_or(0);
                    out.push(Step::Run {
                        command: command.to_string(),
                        exit,
                        shown: Vec::new(),
                    });
                } else if let Some(Step::Run { shown, .. }) = out.last_mut() {
                    shown.push(l.to_string());
                } else {
                    panic!("a ```sh block's line before its first `$ ` command: {l:?}");
                }
            }
        }
    }
    out
}

/// Whether `line` of the output matches `shown` (`...` inside it standing for any text).
fn line_matches(shown: &str, line: &str) -> bool {
    let shown = shown.trim_end();
    let line = line.trim_end();
    let parts: Vec<&str> = shown.split("...").collect();
    if parts.len() == 1 {
        return shown == line;
    }
    let (first, last) = (parts[0], parts[parts.len() - 1]);
    if !line.starts_with(first) || line.len() < first.len() + last.len() || !line.ends_with(last) {
        return false;
    }
    let mut rest = &line[first.len()..line.len() - last.len()];
    for part in &parts[1..parts.len() - 1] {
        match rest.find(part) {
            Some(i) => rest = &rest[i + part.len()..],
            None => return false,
        }
    }
    true
}

/// The first shown line (not `...`) that the output lacks, in order; `None` when all are there.
fn missing_line<'a>(shown: &'a [String], output: &str) -> Option<&'a str> {
    let mut output = output.lines();
    shown
        .iter()
        .filter(|s| s.trim() != "...")
        .find(|s| !output.by_ref().any(|l| line_matches(s, l)))
        .map(String::as_str)
}

#[test]
fn the_convention_reads_files_commands_and_elisions() {
    let page = "text\n```toml file=p/a.toml\nx = 1\n```\n```sh\n$ petrel check p\nok\n...\nend ... here\n$ false  # exit 1\n```\n```text\n$ not run\n```\n";
    assert_eq!(
        steps(page),
        vec![
            Step::File {
                path: "p/a.toml".into(),
                text: "x = 1\n".into()
            },
            Step::Run {
                command: "petrel check p".into(),
                exit: 0,
                shown: vec!["ok".into(), "...".into(), "end ... here".into()]
            },
            Step::Run {
                command: "false  # exit 1".into(),
                exit: 1,
                shown: vec![]
            },
        ]
    );
    let shown: Vec<String> = vec!["ok".into(), "...".into(), "end ... here".into()];
    assert_eq!(missing_line(&shown, "ok\nmore\nend 12 s here\n"), None);
    assert_eq!(
        missing_line(&shown, "end 12 s here\nok\n"),
        Some("end ... here")
    );
    assert_eq!(
        missing_line(&shown, "ok\nend here, late\n"),
        Some("end ... here")
    );
    assert!(!line_matches("a...b", "ab-"));
    assert!(line_matches("a...b...c", "a1b2c"));
    assert!(!line_matches("a...b...c", "a1c2b"));
}

#[test]
fn the_getting_started_page_runs_as_written() {
    let page = std::fs::read_to_string(repo().join("docs/getting-started.md")).unwrap();
    let vehicle = Forget(unique_vehicle("gs"));
    let page = page.replace("patrol1", &vehicle.0);
    let steps = steps(&page);
    let runs = steps
        .iter()
        .filter(|s| matches!(s, Step::Run { .. }))
        .count();
    assert!(runs >= 7, "the page's commands were not found: {steps:?}");

    let work = Workdir::new();
    let bin_dir = petrel_bin().parent().unwrap().to_path_buf();
    let path = format!(
        "{}:{}",
        bin_dir.display(),
        std::env::var("PATH").unwrap_or_default()
    );
    for step in &steps {
        match step {
            Step::File { path, text } => {
                let file = work.path().join(path);
                std::fs::create_dir_all(file.parent().unwrap()).unwrap();
                std::fs::write(&file, text).unwrap();
            }
            Step::Run {
                command,
                exit,
                shown,
            } => {
                let o = Command::new("sh")
                    .arg("-c")
                    .arg(format!("{command} 2>&1"))
                    .current_dir(work.path())
                    .env("PATH", &path)
                    .env("CARGO_TARGET_DIR", repo().join("target/prototypes"))
                    .output()
                    .expect("sh runs");
                let output = String::from_utf8_lossy(&o.stdout);
                assert_eq!(
                    o.status.code(),
                    Some(*exit),
                    "`{command}`: not the exit code the page says ({}):\n{output}",
                    o.status
                );
                if let Some(line) = missing_line(shown, &output) {
                    panic!("`{command}` did not print, in the page's order, the line\n  {line}\nit printed:\n{output}");
                }
            }
        }
    }
}

/// A vehicle whose leftovers in shared memory go, pass or fail.
struct Forget(String);

impl Drop for Forget {
    fn drop(&mut self) {
        forget_vehicle(&self.0);
    }
}
