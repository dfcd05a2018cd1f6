//! The map as SVG, written here for both `petrel plot` (a file) and `petrel monitor`
//! (`/api/map.svg`, inlined in the page). Everything is drawn with presentation attributes
//! (`fill`, `stroke`...), no `<style>` and no `style=""`, so the page's Content Security
//! Policy takes it as it is.
//!
//! The extent holds everything drawn (the map's shapes, the tracks, routes and marks), a metre
//! as long east as north; a label that would leave the plot is put on the other side of its
//! mark, and the legend has a column of its own, so that nothing is cut off or covered.

use super::feed::MapState;
use super::{metres, AreaKind, Coords, Map, Shape, TrackFrom};
use std::fmt::Write as _;

/// The tracks' colours, in order (the first is the vehicle's).
const TRACK_COLORS: [&str; 5] = ["#1a9641", "#252525", "#e7298a", "#a6611a", "#0571b0"];
/// The planned routes' colours, by route of the map (drawn dashed).
const ROUTE_COLORS: [&str; 4] = ["#e08214", "#35978f", "#b8860b", "#8c510a"];
/// Marked events.
const MARK_COLOR: &str = "#111111";
/// The plot's background.
const SEA: &str = "#edf3f8";
/// Text size, px.
const FONT: f64 = 12.0;
/// The legend's column, px.
const LEGEND_W: f64 = 240.0;

fn area_colors(kind: AreaKind) -> (&'static str, &'static str) {
    // (outline, fill)
    match kind {
        AreaKind::Survey => ("#2b5fd9", "#2b5fd9"),
        AreaKind::Forbidden => ("#d7301f", "#d7301f"),
        AreaKind::End => ("#8c2d9e", "#8c2d9e"),
        AreaKind::Zone => ("#6b6b6b", "#9a9a9a"),
    }
}

/// XML text.
fn esc(s: &str) -> String {
    let mut out = String::with_capacity(s.len());
    for c in s.chars() {
        match c {
            '&' => out.push_str("&amp;"),
            '<' => out.push_str("&lt;"),
            '>' => out.push_str("&gt;"),
            '"' => out.push_str("&quot;"),
            c => out.push(c),
        }
    }
    out
}

/// A width in px for `s` at `size` px (a sans-serif's average, generous so that nothing is
/// cut).
fn text_width(s: &str, size: f64) -> f64 {
    s.chars().count() as f64 * size * 0.6
}

/// A round length near `x` (1, 2 or 5 times a power of ten).
fn nice(x: f64) -> f64 {
    if !(x.is_finite() && x > 0.0) {
        return 1.0;
    }
    let p = 10f64.powf(x.log10().floor());
    let m = x / p;
    p * if m < 1.5 {
        1.0
    } else if m < 3.5 {
        2.0
    } else if m < 7.5 {
        5.0
    } else {
        10.0
    }
}

/// A number with as few decimals as `step` needs.
fn tick_text(v: f64, step: f64) -> String {
    let decimals = (-step.log10().floor()).clamp(0.0, 6.0) as usize;
    // Not `-0`: a tick at zero computed as a tiny negative number.
    let v = if v.abs() < step * 1e-6 { 0.0 } else { v };
    format!("{v:.decimals$}")
}

/// From the map's coordinates (east, north) to the drawing's px: linear on both axes (a local
/// equirectangular projection for latitude and longitude).
#[derive(Clone, Copy, Debug)]
struct Projection {
    /// px = x0 + kx * east.
    x0: f64,
    kx: f64,
    /// py = y0 - ky * north.
    y0: f64,
    ky: f64,
}

impl Projection {
    fn px(&self, p: (f64, f64)) -> (f64, f64) {
        (self.x0 + self.kx * p.0, self.y0 - self.ky * p.1)
    }
    fn east(&self, px: f64) -> f64 {
        (px - self.x0) / self.kx
    }
    fn north(&self, py: f64) -> f64 {
        (self.y0 - py) / self.ky
    }
}

/// The plot's rectangle in px.
#[derive(Clone, Copy, Debug)]
struct Plot {
    left: f64,
    top: f64,
    right: f64,
    bottom: f64,
}

/// Every position drawn, in the map's coordinates.
fn everything(map: &Map, state: &MapState) -> Vec<(f64, f64)> {
    let mut pts: Vec<(f64, f64)> = Vec::new();
    for s in &map.shapes {
        match s {
            Shape::Area { ring, .. } => pts.extend(ring),
            Shape::Line { points, .. } => pts.extend(points),
            Shape::Point { at, .. } => pts.push(*at),
        }
    }
    for t in &state.tracks {
        pts.extend(t.iter().map(|s| (s.e, s.n)));
    }
    for r in &state.routes {
        pts.extend(&r.points);
    }
    pts.extend(state.marks.iter().map(|m| m.at));
    pts.retain(|p| p.0.is_finite() && p.1.is_finite());
    pts
}

/// The projection that shows `pts` in `plot`, a metre as long east as north, with a margin.
fn fit(coords: Coords, pts: &[(f64, f64)], plot: Plot) -> Projection {
    let (mut e0, mut e1, mut n0, mut n1) = pts.iter().fold(
        (
            f64::INFINITY,
            f64::NEG_INFINITY,
            f64::INFINITY,
            f64::NEG_INFINITY,
        ),
        |(a, b, c, d), p| (a.min(p.0), b.max(p.0), c.min(p.1), d.max(p.1)),
    );
    if !e0.is_finite() {
        (e0, e1, n0, n1) = (0.0, 0.0, 0.0, 0.0);
    }
    let centre = ((e0 + e1) / 2.0, (n0 + n1) / 2.0);
    // Metres per unit of each axis at the centre.
    let (mx, _) = metres(coords, centre, (centre.0 + 1.0, centre.1));
    let (_, my) = metres(coords, centre, (centre.0, centre.1 + 1.0));
    let (w_m, h_m) = ((e1 - e0) * mx, (n1 - n0) * my);
    // A margin of 6 %, and 20 m at least: a vehicle alone at one point still shows where.
    let pad = (0.06 * w_m.max(h_m)).max(20.0);
    let (w_m, h_m) = (w_m + 2.0 * pad, h_m + 2.0 * pad);
    let (pw, ph) = (plot.right - plot.left, plot.bottom - plot.top);
    let px_per_m = (pw / w_m).min(ph / h_m);
    let (kx, ky) = (px_per_m * mx, px_per_m * my);
    let (cx, cy) = (
        (plot.left + plot.right) / 2.0,
        (plot.top + plot.bottom) / 2.0,
    );
    Projection {
        x0: cx - kx * centre.0,
        kx,
        y0: cy + ky * centre.1,
        ky,
    }
}

fn polyline(out: &mut String, pts: &[(f64, f64)], attrs: &str) {
    let _ = write!(out, "<polyline points=\"");
    for (i, p) in pts.iter().enumerate() {
        if i > 0 {
            out.push(' ');
        }
        let _ = write!(out, "{:.1},{:.1}", p.0, p.1);
    }
    let _ = writeln!(out, "\" fill=\"none\" {attrs}/>");
}

/// Text with a white halo, readable over anything.
fn halo_text(out: &mut String, x: f64, y: f64, anchor: &str, size: f64, color: &str, text: &str) {
    let _ = writeln!(
        out,
        "<text x=\"{x:.1}\" y=\"{y:.1}\" text-anchor=\"{anchor}\" font-size=\"{size}\" fill=\"{color}\" stroke=\"#ffffff\" stroke-width=\"3\" stroke-linejoin=\"round\" paint-order=\"stroke\">{}</text>",
        esc(text)
    );
}

/// The map drawing: `w` x `h` px, with `note` under the title (a replay's time).
pub fn map_svg(map: &Map, state: &MapState, w: u32, h: u32, note: Option<&str>) -> String {
    let (w, h) = (f64::from(w.clamp(320, 8000)), f64::from(h.clamp(240, 8000)));
    let legend_w = LEGEND_W.min(w * 0.35);
    let plot = Plot {
        left: 64.0,
        top: 44.0,
        right: w - legend_w - 16.0,
        bottom: h - 36.0,
    };
    let proj = fit(map.coords, &everything(map, state), plot);
    let mut out = String::new();
    let _ = writeln!(
        out,
        "<svg xmlns=\"http://www.w3.org/2000/svg\" viewBox=\"0 0 {w} {h}\" width=\"{w}\" height=\"{h}\" font-family=\"Helvetica, Arial, sans-serif\" data-map=\"{}\">",
        esc(&map.title)
    );
    let _ = writeln!(
        out,
        "<rect x=\"0\" y=\"0\" width=\"{w}\" height=\"{h}\" fill=\"#ffffff\"/>"
    );
    let title = match note {
        Some(n) => format!("{}: {n}", map.title),
        None => map.title.clone(),
    };
    halo_text(&mut out, plot.left, 26.0, "start", 16.0, "#222222", &title);
    let _ = writeln!(
        out,
        "<rect x=\"{:.1}\" y=\"{:.1}\" width=\"{:.1}\" height=\"{:.1}\" fill=\"{SEA}\" stroke=\"#9aa8b5\"/>",
        plot.left,
        plot.top,
        plot.right - plot.left,
        plot.bottom - plot.top
    );
    axes(&mut out, map.coords, &proj, plot);
    shapes(&mut out, map, &proj);
    routes(&mut out, map, state, &proj);
    tracks(&mut out, state, &proj);
    marks(&mut out, state, &proj, plot);
    scale_bar(&mut out, map.coords, &proj, plot);
    north(&mut out, plot);
    legend(&mut out, map, state, w - legend_w, plot.top, legend_w - 8.0);
    out.push_str("</svg>\n");
    out
}

/// Grid lines and their values along the left and bottom edges.
fn axes(out: &mut String, coords: Coords, proj: &Projection, plot: Plot) {
    let (e0, e1) = (proj.east(plot.left), proj.east(plot.right));
    let (n0, n1) = (proj.north(plot.bottom), proj.north(plot.top));
    let (se, sn) = (nice((e1 - e0) / 6.0), nice((n1 - n0) / 6.0));
    let (ex, ny) = match coords {
        Coords::Xy { .. } => ("x", "y"),
        Coords::LatLon => ("lon", "lat"),
    };
    out.push_str("<g data-layer=\"axes\">\n");
    let mut e = (e0 / se).ceil() * se;
    while e <= e1 {
        let (x, _) = proj.px((e, 0.0));
        let _ = writeln!(
            out,
            "<line x1=\"{x:.1}\" y1=\"{:.1}\" x2=\"{x:.1}\" y2=\"{:.1}\" stroke=\"#d3dde6\"/>",
            plot.top, plot.bottom
        );
        let _ = writeln!(
            out,
            "<text x=\"{x:.1}\" y=\"{:.1}\" text-anchor=\"middle\" font-size=\"11\" fill=\"#555555\">{}</text>",
            plot.bottom + 14.0,
            tick_text(e, se)
        );
        e += se;
    }
    let mut n = (n0 / sn).ceil() * sn;
    while n <= n1 {
        let (_, y) = proj.px((0.0, n));
        let _ = writeln!(
            out,
            "<line x1=\"{:.1}\" y1=\"{y:.1}\" x2=\"{:.1}\" y2=\"{y:.1}\" stroke=\"#d3dde6\"/>",
            plot.left, plot.right
        );
        let _ = writeln!(
            out,
            "<text x=\"{:.1}\" y=\"{:.1}\" text-anchor=\"end\" font-size=\"11\" fill=\"#555555\">{}</text>",
            plot.left - 4.0,
            y + 4.0,
            tick_text(n, sn)
        );
        n += sn;
    }
    let _ = writeln!(
        out,
        "<text x=\"{:.1}\" y=\"{:.1}\" text-anchor=\"end\" font-size=\"11\" fill=\"#555555\">{ex} \u{2192}</text>",
        plot.right,
        plot.bottom + 28.0
    );
    let _ = writeln!(
        out,
        "<text x=\"{:.1}\" y=\"{:.1}\" text-anchor=\"end\" font-size=\"11\" fill=\"#555555\">{ny} \u{2191}</text>",
        plot.left - 4.0,
        plot.top - 6.0
    );
    out.push_str("</g>\n");
}

fn shapes(out: &mut String, map: &Map, proj: &Projection) {
    out.push_str("<g data-layer=\"shapes\">\n");
    for s in &map.shapes {
        if let Shape::Area { name, kind, ring } = s {
            let (line, fill) = area_colors(*kind);
            let pts: Vec<(f64, f64)> = ring.iter().map(|p| proj.px(*p)).collect();
            let _ = write!(out, "<polygon data-area=\"{}\" points=\"", esc(name));
            for p in &pts {
                let _ = write!(out, "{:.1},{:.1} ", p.0, p.1);
            }
            let _ = writeln!(
                out,
                "\" fill=\"{fill}\" fill-opacity=\"0.22\" stroke=\"{line}\" stroke-width=\"2\"/>"
            );
            let n = pts.len().max(1) as f64;
            let c = pts
                .iter()
                .fold((0.0, 0.0), |a, p| (a.0 + p.0 / n, a.1 + p.1 / n));
            halo_text(out, c.0, c.1 + 4.0, "middle", FONT, line, name);
        }
    }
    for s in &map.shapes {
        match s {
            Shape::Line { name, points } => {
                let pts: Vec<(f64, f64)> = points.iter().map(|p| proj.px(*p)).collect();
                polyline(
                    out,
                    &pts,
                    &format!(
                        "data-line=\"{}\" stroke=\"#333333\" stroke-width=\"1.5\"",
                        esc(name)
                    ),
                );
            }
            Shape::Point { name, at } => {
                let (x, y) = proj.px(*at);
                let _ = writeln!(
                    out,
                    "<polygon data-point=\"{}\" points=\"{:.1},{:.1} {:.1},{:.1} {:.1},{:.1}\" fill=\"#333333\"/>",
                    esc(name),
                    x,
                    y - 7.0,
                    x - 6.0,
                    y + 5.0,
                    x + 6.0,
                    y + 5.0
                );
                halo_text(out, x + 9.0, y + 4.0, "start", FONT, "#333333", name);
            }
            Shape::Area { .. } => {}
        }
    }
    out.push_str("</g>\n");
}

fn routes(out: &mut String, map: &Map, state: &MapState, proj: &Projection) {
    let _ = writeln!(
        out,
        "<g data-layer=\"routes\" data-count=\"{}\">",
        state.routes.len()
    );
    let last = state.routes.len().saturating_sub(1);
    for (i, r) in state.routes.iter().enumerate() {
        let pts: Vec<(f64, f64)> = r.points.iter().map(|p| proj.px(*p)).collect();
        // The latest route the plan gave is the one flown: the older ones fade.
        let opacity = if i == last { 1.0 } else { 0.55 };
        let color = ROUTE_COLORS[r.source % ROUTE_COLORS.len()];
        polyline(
            out,
            &pts,
            &format!(
                "data-route=\"{}\" stroke=\"{color}\" stroke-width=\"2\" stroke-dasharray=\"7 4\" stroke-opacity=\"{opacity}\"",
                esc(&map.routes[r.source].name)
            ),
        );
        for p in &pts {
            let _ = writeln!(
                out,
                "<circle cx=\"{:.1}\" cy=\"{:.1}\" r=\"2.5\" fill=\"{color}\" fill-opacity=\"{opacity}\"/>",
                p.0, p.1
            );
        }
    }
    out.push_str("</g>\n");
}

fn tracks(out: &mut String, state: &MapState, proj: &Projection) {
    out.push_str("<g data-layer=\"tracks\">\n");
    for (i, t) in state.tracks.iter().enumerate() {
        let color = TRACK_COLORS[i % TRACK_COLORS.len()];
        let pts: Vec<(f64, f64)> = t.iter().map(|s| proj.px((s.e, s.n))).collect();
        polyline(
            out,
            &pts,
            &format!(
                "data-track=\"{i}\" data-points=\"{}\" stroke=\"{color}\" stroke-width=\"2.5\" stroke-linejoin=\"round\"",
                pts.len()
            ),
        );
        if let Some(p) = pts.last() {
            // Where it is now.
            let _ = writeln!(
                out,
                "<circle data-now=\"{i}\" cx=\"{:.1}\" cy=\"{:.1}\" r=\"6\" fill=\"{color}\" stroke=\"#ffffff\" stroke-width=\"2\"/>",
                p.0, p.1
            );
        }
    }
    out.push_str("</g>\n");
}

fn marks(out: &mut String, state: &MapState, proj: &Projection, plot: Plot) {
    let _ = writeln!(
        out,
        "<g data-layer=\"marks\" data-count=\"{}\">",
        state.marks.len()
    );
    let mut placed: Vec<(f64, f64)> = Vec::new();
    for m in &state.marks {
        let (x, y) = proj.px(m.at);
        // Marks at one place (a fault and its alarm) get their labels stacked, not overlaid.
        let stacked = placed
            .iter()
            .filter(|p| (p.0 - x).hypot(p.1 - y) < 16.0)
            .count();
        placed.push((x, y));
        let _ = writeln!(
            out,
            "<path d=\"M{:.1},{:.1} l10,10 m0,-10 l-10,10\" stroke=\"{MARK_COLOR}\" stroke-width=\"2\"/>",
            x - 5.0,
            y - 5.0
        );
        let width = text_width(&m.label, FONT);
        let mut ty = y - 8.0 - 14.0 * stacked as f64;
        if ty < plot.top + FONT {
            ty = y + 18.0 + 14.0 * stacked as f64;
        }
        // Right of the mark, or left of it when that would leave the plot.
        let (tx, anchor) = if x + 8.0 + width > plot.right && x - 8.0 - width >= 0.0 {
            (x - 8.0, "end")
        } else {
            (x + 8.0, "start")
        };
        halo_text(out, tx, ty, anchor, FONT, MARK_COLOR, &m.label);
    }
    out.push_str("</g>\n");
}

/// A bar of a round length, bottom left.
fn scale_bar(out: &mut String, coords: Coords, proj: &Projection, plot: Plot) {
    let (e0, e1) = (proj.east(plot.left), proj.east(plot.right));
    let n = proj.north((plot.top + plot.bottom) / 2.0);
    let (width_m, _) = metres(coords, (e0, n), (e1, n));
    let px_per_m = (plot.right - plot.left) / width_m.max(1e-9);
    let len = nice(width_m / 5.0);
    let px = len * px_per_m;
    let (x, y) = (plot.left + 14.0, plot.bottom - 16.0);
    let text = if len >= 1000.0 {
        format!("{} km", len / 1000.0)
    } else {
        format!("{len} m")
    };
    let _ = writeln!(
        out,
        "<g data-layer=\"scale\" data-metres=\"{len}\"><rect x=\"{:.1}\" y=\"{:.1}\" width=\"{:.1}\" height=\"26\" fill=\"#ffffff\" fill-opacity=\"0.8\"/><path d=\"M{x:.1},{:.1} v6 h{px:.1} v-6\" fill=\"none\" stroke=\"#222222\" stroke-width=\"2\"/><text x=\"{:.1}\" y=\"{:.1}\" text-anchor=\"middle\" font-size=\"11\" fill=\"#222222\">{text}</text></g>",
        x - 6.0,
        y - 14.0,
        px + 12.0,
        y - 2.0,
        x + px / 2.0,
        y - 4.0
    );
}

fn north(out: &mut String, plot: Plot) {
    let (x, y) = (plot.right - 20.0, plot.top + 14.0);
    let _ = writeln!(
        out,
        "<g data-layer=\"north\"><path d=\"M{x:.1},{y:.1} l-6,16 l6,-4 l6,4 z\" fill=\"#222222\"/><text x=\"{x:.1}\" y=\"{:.1}\" text-anchor=\"middle\" font-size=\"11\" fill=\"#222222\">N</text></g>",
        y + 30.0
    );
}

/// `text` in lines of at most `chars` characters, broken between words.
fn wrap(text: &str, chars: usize) -> Vec<String> {
    let mut lines: Vec<String> = Vec::new();
    for word in text.split(' ') {
        match lines.last_mut() {
            Some(l) if l.chars().count() + 1 + word.chars().count() <= chars => {
                l.push(' ');
                l.push_str(word);
            }
            _ => lines.push(word.to_string()),
        }
    }
    lines
}

fn legend(out: &mut String, map: &Map, state: &MapState, x: f64, top: f64, width: f64) {
    // (swatch, text)
    enum Swatch {
        Area(AreaKind),
        Line(&'static str, bool),
        Point,
        Mark,
    }
    let mut items: Vec<(Swatch, String)> = Vec::new();
    let mut kinds: Vec<AreaKind> = map
        .shapes
        .iter()
        .filter_map(|s| match s {
            Shape::Area { kind, .. } => Some(*kind),
            _ => None,
        })
        .collect();
    kinds.sort();
    kinds.dedup();
    for k in kinds {
        items.push((Swatch::Area(k), k.legend().to_string()));
    }
    for s in &map.shapes {
        match s {
            Shape::Line { name, .. } => items.push((Swatch::Line("#333333", false), name.clone())),
            Shape::Point { name, .. } => items.push((Swatch::Point, name.clone())),
            Shape::Area { .. } => {}
        }
    }
    for (i, r) in map.routes.iter().enumerate() {
        let n = state.routes.iter().filter(|x| x.source == i).count();
        items.push((
            Swatch::Line(ROUTE_COLORS[i % ROUTE_COLORS.len()], true),
            format!("{} ({n})", r.name),
        ));
    }
    for (i, t) in map.tracks.iter().enumerate() {
        let from = match &t.from {
            TrackFrom::Signals { x, y, .. } => format!("{x}, {y}"),
            TrackFrom::Event { event, .. } => format!("event {event}"),
        };
        let n = state.tracks.get(i).map_or(0, Vec::len);
        items.push((
            Swatch::Line(TRACK_COLORS[i % TRACK_COLORS.len()], false),
            format!(
                "{} ({from}; {n} position{})",
                t.name,
                if n == 1 { "" } else { "s" }
            ),
        ));
    }
    if !map.marks.is_empty() {
        items.push((
            Swatch::Mark,
            format!("event, where it happened ({})", state.marks.len()),
        ));
    }
    let chars = ((width - 34.0) / (FONT * 0.6)).max(8.0) as usize;
    let mut y = top + 4.0;
    out.push_str("<g data-layer=\"legend\">\n");
    halo_text(out, x, y + 10.0, "start", 13.0, "#222222", "Legend");
    y += 26.0;
    for (swatch, text) in items {
        let (sx, sy) = (x + 2.0, y);
        match swatch {
            Swatch::Area(k) => {
                let (line, fill) = area_colors(k);
                let _ = writeln!(
                    out,
                    "<rect x=\"{sx:.1}\" y=\"{:.1}\" width=\"22\" height=\"12\" fill=\"{fill}\" fill-opacity=\"0.22\" stroke=\"{line}\" stroke-width=\"2\"/>",
                    sy - 10.0
                );
            }
            Swatch::Line(color, dashed) => {
                let dash = if dashed {
                    " stroke-dasharray=\"7 4\""
                } else {
                    ""
                };
                let _ = writeln!(
                    out,
                    "<line x1=\"{sx:.1}\" y1=\"{:.1}\" x2=\"{:.1}\" y2=\"{:.1}\" stroke=\"{color}\" stroke-width=\"2.5\"{dash}/>",
                    sy - 4.0,
                    sx + 22.0,
                    sy - 4.0
                );
            }
            Swatch::Point => {
                let _ = writeln!(
                    out,
                    "<polygon points=\"{:.1},{:.1} {:.1},{:.1} {:.1},{:.1}\" fill=\"#333333\"/>",
                    sx + 11.0,
                    sy - 11.0,
                    sx + 5.0,
                    sy + 1.0,
                    sx + 17.0,
                    sy + 1.0
                );
            }
            Swatch::Mark => {
                let _ = writeln!(
                    out,
                    "<path d=\"M{:.1},{:.1} l10,10 m0,-10 l-10,10\" stroke=\"{MARK_COLOR}\" stroke-width=\"2\"/>",
                    sx + 6.0,
                    sy - 9.0
                );
            }
        }
        for line in wrap(&text, chars) {
            let _ = writeln!(
                out,
                "<text x=\"{:.1}\" y=\"{y:.1}\" font-size=\"{FONT}\" fill=\"#222222\">{}</text>",
                x + 32.0,
                esc(&line)
            );
            y += FONT + 3.0;
        }
        y += 6.0;
    }
    out.push_str("</g>\n");
}

/// The third value of the tracks that have one (a depth, an altitude) against mission time,
/// with the marked events; `None` when no track has one.
pub fn profile_svg(map: &Map, state: &MapState, w: u32, h: u32) -> Option<String> {
    let (i, label, down) = map
        .tracks
        .iter()
        .enumerate()
        .find_map(|(i, t)| match &t.from {
            TrackFrom::Signals {
                z: Some(z),
                z_label,
                z_down,
                ..
            } => Some((i, z_label.clone().unwrap_or_else(|| z.clone()), *z_down)),
            _ => None,
        })?;
    let samples: Vec<(f64, f64)> = state
        .tracks
        .get(i)?
        .iter()
        .filter_map(|s| s.z.map(|z| (s.t, z)))
        .filter(|(t, z)| t.is_finite() && z.is_finite())
        .collect();
    let (w, h) = (f64::from(w.clamp(320, 8000)), f64::from(h.clamp(200, 8000)));
    let plot = Plot {
        left: 64.0,
        top: 40.0,
        right: w - 20.0,
        bottom: h - 40.0,
    };
    let (t0, t1) = samples
        .iter()
        .fold((f64::INFINITY, f64::NEG_INFINITY), |a, s| {
            (a.0.min(s.0), a.1.max(s.0))
        });
    let (t0, t1) = if t0 < t1 { (t0, t1) } else { (0.0, 1.0) };
    let (z0, z1) = samples
        .iter()
        .fold((0.0f64, 1.0f64), |a, s| (a.0.min(s.1), a.1.max(s.1)));
    let span = (z1 - z0).max(1e-9);
    let (z0, z1) = (z0 - 0.05 * span, z1 + 0.05 * span);
    let x = |t: f64| plot.left + (t - t0) / (t1 - t0) * (plot.right - plot.left);
    // A depth grows downwards.
    let y = |z: f64| {
        let f = (z - z0) / (z1 - z0);
        if down {
            plot.top + f * (plot.bottom - plot.top)
        } else {
            plot.bottom - f * (plot.bottom - plot.top)
        }
    };
    let mut out = String::new();
    let _ = writeln!(
        out,
        "<svg xmlns=\"http://www.w3.org/2000/svg\" viewBox=\"0 0 {w} {h}\" width=\"{w}\" height=\"{h}\" font-family=\"Helvetica, Arial, sans-serif\">"
    );
    let _ = writeln!(
        out,
        "<rect x=\"0\" y=\"0\" width=\"{w}\" height=\"{h}\" fill=\"#ffffff\"/>"
    );
    halo_text(
        &mut out,
        plot.left,
        24.0,
        "start",
        16.0,
        "#222222",
        &format!("{}: {label}", map.title),
    );
    let _ = writeln!(
        out,
        "<rect x=\"{:.1}\" y=\"{:.1}\" width=\"{:.1}\" height=\"{:.1}\" fill=\"none\" stroke=\"#9aa8b5\"/>",
        plot.left,
        plot.top,
        plot.right - plot.left,
        plot.bottom - plot.top
    );
    let st = nice((t1 - t0) / 8.0);
    let mut t = (t0 / st).ceil() * st;
    while t <= t1 {
        let _ = writeln!(
            out,
            "<text x=\"{:.1}\" y=\"{:.1}\" text-anchor=\"middle\" font-size=\"11\" fill=\"#555555\">{}</text>",
            x(t),
            plot.bottom + 14.0,
            tick_text(t, st)
        );
        t += st;
    }
    let sz = nice((z1 - z0) / 6.0);
    let mut z = (z0 / sz).ceil() * sz;
    while z <= z1 {
        let _ = writeln!(
            out,
            "<line x1=\"{:.1}\" y1=\"{:.1}\" x2=\"{:.1}\" y2=\"{:.1}\" stroke=\"#e3e8ec\"/><text x=\"{:.1}\" y=\"{:.1}\" text-anchor=\"end\" font-size=\"11\" fill=\"#555555\">{}</text>",
            plot.left,
            y(z),
            plot.right,
            y(z),
            plot.left - 4.0,
            y(z) + 4.0,
            tick_text(z, sz)
        );
        z += sz;
    }
    let _ = writeln!(
        out,
        "<text x=\"{:.1}\" y=\"{:.1}\" text-anchor=\"end\" font-size=\"11\" fill=\"#555555\">mission time (s) \u{2192}</text>",
        plot.right,
        plot.bottom + 30.0
    );
    for m in &state.marks {
        if !(t0..=t1).contains(&m.t) {
            continue;
        }
        let mx = x(m.t);
        let _ = writeln!(
            out,
            "<line x1=\"{mx:.1}\" y1=\"{:.1}\" x2=\"{mx:.1}\" y2=\"{:.1}\" stroke=\"#999999\" stroke-dasharray=\"3 3\"/>",
            plot.top,
            plot.bottom
        );
        let _ = writeln!(
            out,
            "<text transform=\"translate({:.1},{:.1}) rotate(-90)\" text-anchor=\"end\" font-size=\"11\" fill=\"{MARK_COLOR}\">{}</text>",
            mx + 4.0,
            plot.top + 4.0,
            esc(&m.label)
        );
    }
    let pts: Vec<(f64, f64)> = samples.iter().map(|(t, z)| (x(*t), y(*z))).collect();
    polyline(
        &mut out,
        &pts,
        &format!(
            "data-profile=\"{i}\" stroke=\"{}\" stroke-width=\"2\"",
            TRACK_COLORS[i % TRACK_COLORS.len()]
        ),
    );
    out.push_str("</svg>\n");
    Some(out)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::map::feed::{Mark, Sample};
    use std::collections::BTreeMap;

    fn map() -> Map {
        Map {
            title: "bench".into(),
            coords: Coords::Xy { metres: 1.0 },
            shapes: vec![
                Shape::Area {
                    name: "alpha".into(),
                    kind: AreaKind::Survey,
                    ring: vec![(0.0, 0.0), (100.0, 0.0), (100.0, 50.0)],
                },
                Shape::Point {
                    name: "start".into(),
                    at: (0.0, 0.0),
                },
            ],
            tracks: vec![crate::map::TrackSource {
                name: "vehicle".into(),
                from: TrackFrom::Signals {
                    x: "N.x".into(),
                    y: "N.y".into(),
                    z: Some("N.d".into()),
                    z_label: Some("depth (m)".into()),
                    z_down: true,
                },
            }],
            routes: Vec::new(),
            marks: BTreeMap::from([("alarm".to_string(), None)]),
        }
    }

    fn numbers(svg: &str, attr: &str) -> Vec<f64> {
        svg.split(&format!("{attr}=\""))
            .skip(1)
            .filter_map(|s| s.split('"').next()?.parse().ok())
            .collect()
    }

    #[test]
    fn everything_drawn_is_inside_the_drawing_with_its_legend() {
        let m = map();
        let mut s = MapState::new(&m);
        // A track far beyond the map's areas, and a long label at its far end.
        s.tracks[0] = (0..50)
            .map(|i| Sample {
                t: i as f64,
                e: 30.0 * i as f64,
                n: 0.0,
                z: Some(i as f64 / 10.0),
            })
            .collect();
        s.marks.push(Mark {
            t: 49.0,
            at: (1470.0, 0.0),
            label: "surfaced_after_a_very_long_name_for_an_event".into(),
        });
        let svg = map_svg(&m, &s, 1000, 800, Some("t = 49 s"));
        assert!(svg.starts_with("<svg") && svg.trim_end().ends_with("</svg>"));
        assert!(
            !svg.contains("style"),
            "no style: the page's policy refuses it"
        );
        for x in numbers(&svg, "x").into_iter().chain(numbers(&svg, "cx")) {
            assert!((0.0..=1000.0).contains(&x), "x = {x}");
        }
        for y in numbers(&svg, "y").into_iter().chain(numbers(&svg, "cy")) {
            assert!((0.0..=800.0).contains(&y), "y = {y}");
        }
        // The label that would leave the plot on the right is drawn to the left of its mark.
        assert!(svg.contains("text-anchor=\"end\" font-size=\"12\" fill=\"#111111\""));
        // The legend's lines, read together.
        let legend = svg
            .split("data-layer=\"legend\"")
            .nth(1)
            .unwrap_or_default();
        let words: Vec<&str> = legend
            .split("\">")
            .skip(1)
            .filter_map(|t| t.split("</text>").next())
            .filter(|t| !t.contains('<'))
            .collect();
        let legend = words.join(" ");
        for item in [
            "survey area",
            "start",
            "vehicle (N.x, N.y; 50 positions)",
            "Legend",
        ] {
            assert!(legend.contains(item), "{item} in {legend}");
        }
        assert!(svg.contains("data-points=\"50\""));
        assert!(svg.contains("data-layer=\"scale\""));
        let profile = profile_svg(&m, &s, 1000, 400).expect("a depth profile");
        assert!(profile.contains("data-profile=\"0\"") && profile.contains("depth (m)"));
    }

    #[test]
    fn latitude_and_longitude_keep_a_metre_as_long_east_as_north() {
        let mut m = map();
        m.coords = Coords::LatLon;
        m.shapes = vec![Shape::Area {
            name: "square".into(),
            kind: AreaKind::Zone,
            // About 1 km each way at 48.7 degrees north.
            ring: vec![
                (2.20, 48.70),
                (2.2136, 48.70),
                (2.2136, 48.709),
                (2.20, 48.709),
            ],
        }];
        m.tracks.clear();
        let s = MapState::new(&m);
        let plot = Plot {
            left: 0.0,
            top: 0.0,
            right: 1000.0,
            bottom: 1000.0,
        };
        let pts = everything(&m, &s);
        let p = fit(m.coords, &pts, plot);
        let (a, b, c) = (
            p.px((2.20, 48.70)),
            p.px((2.2136, 48.70)),
            p.px((2.20, 48.709)),
        );
        let (east, north) = ((b.0 - a.0).abs(), (c.1 - a.1).abs());
        assert!(
            (east / north - 1.0).abs() < 0.02,
            "{east} px east, {north} px north"
        );
        assert!(map_svg(&m, &s, 800, 600, None).contains("lat"));
    }

    #[test]
    fn round_lengths() {
        assert_eq!(nice(0.9), 1.0);
        assert_eq!(nice(180.0), 200.0);
        assert_eq!(nice(4200.0), 5000.0);
        assert_eq!(
            wrap("a long name of a track", 10),
            ["a long", "name of a", "track"]
        );
    }
}
