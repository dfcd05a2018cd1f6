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
use std::collections::HashMap;
use std::io::Write;
use std::process::{Command, Stdio};
use std::sync::{Arc, Mutex};

/// The SVG drawings the page shows.
pub struct Drawing {
    /// Every net, its places, transitions and arcs (`petrel dot`).
    pub nets: String,
    /// The tree of nets: children and activations (`petrel dot --tree`).
    pub tree: String,
    /// Each net alone ([`petrel_nets::dot::instance_dot`]: its global places as ports), laid
    /// out the first time a page asks for it, then kept.
    pub each: NetLayouts,
}

/// The drawings of the nets one by one: a page opens one net at a time, so each is laid out
/// when first asked for (a few tens of milliseconds), then served from memory.
pub struct NetLayouts {
    project: Project,
    done: Mutex<HashMap<String, Arc<str>>>,
}

impl NetLayouts {
    /// The drawing of net `name` (a name the player uses: `MISSION/PHASES`); an error names
    /// the nets there are.
    pub fn get(&self, name: &str) -> Result<Arc<str>, String> {
        if let Some(svg) = self.lock().get(name) {
            return Ok(svg.clone());
        }
        let dot = petrel_nets::dot::instance_dot(&self.project, name)?;
        let mut svg = svg_body(&graphviz(&dot)?);
        // Left to right reads best, but a long net laid out so is a strip that a canvas shows
        // tiny or in part: then top to bottom, if that is the one a canvas shows larger.
        if let Some((w, h)) = view_box(&svg).filter(|(w, h)| *w > 1.6 * *h) {
            let tb = dot.replacen("rankdir=LR", "rankdir=TB", 1);
            let other = svg_body(&graphviz(&tb)?);
            if let Some((w2, h2)) = view_box(&other) {
                let fits = |w: f64, h: f64| (CANVAS.0 / w).min(CANVAS.1 / h);
                if fits(w2, h2) > fits(w, h) {
                    svg = other;
                }
            }
        }
        let svg: Arc<str> = svg.into();
        self.lock().insert(name.to_string(), svg.clone());
        Ok(svg)
    }

    fn lock(&self) -> std::sync::MutexGuard<'_, HashMap<String, Arc<str>>> {
        self.done.lock().unwrap_or_else(|e| e.into_inner())
    }
}

/// The canvas a net's drawing is laid out for (px): a 1600 x 1000 window's, about.
const CANVAS: (f64, f64) = (900.0, 800.0);

/// The width and height of an SVG's `viewBox`.
fn view_box(svg: &str) -> Option<(f64, f64)> {
    let v = svg.split("viewBox=\"").nth(1)?.split('"').next()?;
    let n: Vec<f64> = v
        .split_whitespace()
        .filter_map(|x| x.parse().ok())
        .collect();
    (n.len() == 4 && n[2] > 0.0 && n[3] > 0.0).then(|| (n[2], n[3]))
}

/// Lays out the nets of `project` and their tree.
pub fn draw(project: &Project) -> Result<Drawing, String> {
    let nets_dot = petrel_nets::dot::project_to_dot(project, None)?;
    let tree_dot = petrel_nets::dot::overview_tree_dot(project);
    Ok(Drawing {
        nets: svg_body(&graphviz(&nets_dot)?),
        tree: svg_body(&graphviz(&tree_dot)?),
        each: NetLayouts {
            project: project.clone(),
            done: Mutex::new(HashMap::new()),
        },
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
