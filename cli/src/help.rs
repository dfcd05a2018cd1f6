//! `petrel --help`: the commands grouped by when a user needs them (designing a mission,
//! running a vehicle, after a run), one line each.
//!
//! clap lists subcommands under one heading; the groups are made here, from clap's own model
//! of the commands (each command's name and the first paragraph of its doc comment, its
//! `about`), and put into the top-level help template. A command's long explanation stays in
//! its own `--help`. [`GROUPS`] names every command once: a command missing from it is still
//! shown (under "Other commands"), and the tests refuse that, so a new command cannot be
//! forgotten.

use clap::CommandFactory;

/// The groups of the top-level help, in order, each with its commands in order.
pub const GROUPS: &[(&str, &[&str])] = &[
    (
        "Design a mission",
        &[
            "check", "verify", "run", "fmt", "dot", "gen", "export", "import",
        ],
    ),
    (
        "Run a vehicle",
        &[
            "up", "play", "send", "status", "reload", "monitor", "bridge", "gateway", "keys",
        ],
    ),
    ("After a run", &["replay", "journal", "plot"]),
];

/// The heading of commands no group names (none, when [`GROUPS`] is complete).
const OTHER: &str = "Other commands";

/// The `petrel` command line, with its grouped help.
pub fn command() -> clap::Command {
    let cmd = crate::Cli::command();
    let groups = grouped(&cmd);
    cmd.help_template(format!(
        "{{before-help}}{{about-with-newline}}\n{{usage-heading}} {{usage}}\n\n{groups}\nOptions:\n{{options}}{{after-help}}"
    ))
}

/// The commands under their group headings, one line each: `  name  about`.
fn grouped(cmd: &clap::Command) -> String {
    let shown: Vec<&clap::Command> = cmd
        .get_subcommands()
        .filter(|c| !c.is_hide_set() && c.get_name() != "help")
        .collect();
    let width = shown.iter().map(|c| c.get_name().len()).max().unwrap_or(0);
    let line = |c: &clap::Command| {
        let about = c.get_about().map(|a| a.to_string()).unwrap_or_default();
        // Braces would read as template tags.
        let about = about.replace('{', "{{").replace('}', "}}");
        format!("  {:<width$}  {about}\n", c.get_name())
    };
    let mut text = String::new();
    let mut section = |heading: &str, members: Vec<&clap::Command>| {
        if members.is_empty() {
            return;
        }
        if !text.is_empty() {
            text.push('\n');
        }
        text.push_str(heading);
        text.push_str(":\n");
        for c in members {
            text.push_str(&line(c));
        }
    };
    for (heading, names) in GROUPS {
        let members = names
            .iter()
            .filter_map(|n| shown.iter().copied().find(|c| c.get_name() == *n))
            .collect();
        section(heading, members);
    }
    let others = shown
        .iter()
        .copied()
        .filter(|c| !GROUPS.iter().any(|(_, n)| n.contains(&c.get_name())))
        .collect();
    section(OTHER, others);
    text
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The top-level help as `petrel --help` prints it.
    fn help() -> String {
        command().render_help().to_string()
    }

    #[test]
    fn every_command_is_in_exactly_one_group_in_order() {
        let text = help();
        let cmd = crate::Cli::command();
        let visible: Vec<&str> = cmd
            .get_subcommands()
            .filter(|c| !c.is_hide_set() && c.get_name() != "help")
            .map(|c| c.get_name())
            .collect();
        assert!(!text.contains(OTHER), "a command is in no group:\n{text}");
        // Each group's heading, then its commands, one per line, in the order of GROUPS.
        let lines: Vec<&str> = text.lines().collect();
        let mut listed = Vec::new();
        for (heading, names) in GROUPS {
            let at = lines
                .iter()
                .position(|l| *l == format!("{heading}:"))
                .unwrap_or_else(|| panic!("no `{heading}:` heading:\n{text}"));
            let firsts: Vec<&str> = lines[at + 1..]
                .iter()
                .take_while(|l| l.starts_with("  "))
                .map(|l| l.split_whitespace().next().unwrap_or(""))
                .collect();
            assert_eq!(&firsts, names, "the commands under `{heading}`:\n{text}");
            listed.extend(firsts);
        }
        for name in &visible {
            let times = listed.iter().filter(|n| *n == name).count();
            assert_eq!(times, 1, "`{name}` listed {times} times:\n{text}");
        }
        assert_eq!(
            listed.len(),
            visible.len(),
            "{listed:?} against {visible:?}"
        );
        assert!(!text.contains("__exec"), "{text}");
    }

    #[test]
    fn each_command_takes_one_short_line_and_keeps_its_long_help() {
        let text = help();
        for (_, names) in GROUPS {
            for name in *names {
                let line = text
                    .lines()
                    .find(|l| l.split_whitespace().next() == Some(name))
                    .unwrap_or_else(|| panic!("no line for `{name}`"));
                assert!(
                    line.chars().count() <= 100,
                    "`{name}`'s line is {} characters: {line}",
                    line.chars().count()
                );
                assert!(!line.trim_end().ends_with('.'), "{line}");
            }
        }
        // The details are in the command's own help.
        let up = command()
            .find_subcommand_mut("up")
            .expect("up")
            .render_long_help()
            .to_string();
        assert!(up.contains("restart what fails"), "{up}");
    }
}
