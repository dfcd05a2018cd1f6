//! The drawing of the nets, laid out once by Graphviz.
//!
//! `petrel dot` already draws a project as Petri nets (places circles, transitions boxes saying
//! their event and actions, one cluster per net, global places outside every cluster); Graphviz's
//! `dot` lays that out as SVG, whose nodes carry their DOT ids as titles. The page keeps the SVG
//! as it is and changes only classes on it, so the layout is computed once per monitor, not per
//! step. Why Graphviz rather than a Rust layout crate: it is the one layered layout with
//! clusters (each net a box, shared places between them) that reads well on forty nets, and it
//! is one Debian package (`graphviz`) away.

use petrel_nets::model::Project;
use std::io::Write;
use std::process::{Command, Stdio};

/// The SVG drawings the page shows.
pub struct Drawing {
    /// Every net, its places, transitions and arcs (`petrel dot`).
    pub nets: String,
    /// The tree of nets: children and activations (`petrel dot --tree`).
    pub tree: String,
}

/// Lays out the nets of `project` and their tree.
pub fn draw(project: &Project) -> Result<Drawing, String> {
    let nets_dot = petrel_nets::dot::project_to_dot(project, None)?;
    // The tree sits in a narrow side panel: left to right, it grows down, not across.
    let tree_dot =
        petrel_nets::dot::project_tree_dot(project).replacen("rankdir=TB", "rankdir=LR", 1);
    Ok(Drawing {
        nets: svg_body(&graphviz(&nets_dot)?),
        tree: svg_body(&graphviz(&tree_dot)?),
    })
}

/// Runs `dot -Tsvg` on `text`.
fn graphviz(text: &str) -> Result<String, String> {
    let missing = |e: std::io::Error| {
        format!(
            "petrel monitor lays the nets out with Graphviz, and `dot` could not be run ({e}): install it (Debian: apt-get install graphviz)"
        )
    };
    let mut child = Command::new("dot")
        .arg("-Tsvg")
        .stdin(Stdio::piped())
        .stdout(Stdio::piped())
        .stderr(Stdio::piped())
        .spawn()
        .map_err(missing)?;
    // Write from another thread: `dot` may fill its output pipe before it has read all of ours.
    let mut stdin = child.stdin.take().ok_or("no pipe to Graphviz")?;
    let input = text.to_owned();
    let writer = std::thread::spawn(move || stdin.write_all(input.as_bytes()));
    let out = child.wait_with_output().map_err(missing)?;
    let written = writer.join().map_err(|_| "writing to Graphviz failed")?;
    if !out.status.success() {
        return Err(format!(
            "Graphviz could not lay the nets out ({}): {}",
            out.status,
            String::from_utf8_lossy(&out.stderr).trim()
        ));
    }
    written.map_err(|e| format!("cannot write to Graphviz: {e}"))?;
    String::from_utf8(out.stdout).map_err(|_| "Graphviz wrote SVG that is not UTF-8".to_string())
}

/// The `<svg>` element alone (no XML declaration or DOCTYPE), to sit inside the page.
fn svg_body(svg: &str) -> String {
    match svg.find("<svg") {
        Some(i) => svg[i..].to_string(),
        None => svg.to_string(),
    }
}
