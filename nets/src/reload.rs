//! Reloading a project mid-mission (docs/semantics.md, "Reloading a project mid-mission"):
//! the state of the running version mapped onto a new version by names, or the reasons it
//! cannot be.
//!
//! Sans-I/O: [`Mapping::parse`] reads the mapping file's text, [`map_state`] takes the old
//! compiled project with its state (bits, timers' deadlines, activation arguments) and the new
//! compiled project, and gives the new state or every reason for a refusal. Verifying the new
//! version from the mapped state is [`crate::verify::verify_from`]; the player does the rest.

use crate::compiled::{CompiledProject, NetId, PlaceRef, Value};
use crate::semantics::Layout;
use serde::Deserialize;
use std::collections::BTreeMap;

/// The mapping file (`reload.toml`): renames, and what to do with what vanished. Names on the
/// left (and in `vanished`) are the old version's, on the right the new version's.
#[derive(Clone, Debug, Default, PartialEq, Eq)]
pub struct Mapping {
    /// Old net name to new net name.
    pub nets: BTreeMap<String, String>,
    /// Old `NET.place` / `global.place` to new ones.
    pub places: BTreeMap<String, String>,
    /// Old timer name to new timer name.
    pub timers: BTreeMap<String, String>,
    /// Old places whose token is dropped (they are gone from the new version).
    pub vanished_places: Vec<String>,
    /// Old nets dropped with their tokens.
    pub vanished_nets: Vec<String>,
    /// Old timers cancelled.
    pub vanished_timers: Vec<String>,
}

#[derive(Deserialize, Default)]
#[serde(deny_unknown_fields)]
struct FileRename {
    #[serde(default)]
    nets: BTreeMap<String, String>,
    #[serde(default)]
    places: BTreeMap<String, String>,
    #[serde(default)]
    timers: BTreeMap<String, String>,
}

#[derive(Deserialize, Default)]
#[serde(deny_unknown_fields)]
struct FileVanished {
    #[serde(default)]
    places: Vec<String>,
    #[serde(default)]
    nets: Vec<String>,
    #[serde(default)]
    timers: Vec<String>,
}

#[derive(Deserialize, Default)]
#[serde(deny_unknown_fields)]
struct File {
    #[serde(default)]
    rename: FileRename,
    #[serde(default)]
    vanished: FileVanished,
}

/// A mapping file that does not read: where (1-based line and column) and what.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct MappingError {
    /// Line, from 1.
    pub line: usize,
    /// Column, from 1.
    pub col: usize,
    /// What is wrong.
    pub message: String,
}

impl std::fmt::Display for MappingError {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        write!(f, "{}:{}: {}", self.line, self.col, self.message)
    }
}

/// Largest mapping file read, in bytes: it names a few nets and places.
pub const MAX_MAPPING_LEN: usize = 64 * 1024;

impl Mapping {
    /// Reads a mapping file's text (an empty text is the empty mapping).
    pub fn parse(text: &str) -> Result<Mapping, MappingError> {
        if text.len() > MAX_MAPPING_LEN {
            return Err(MappingError {
                line: 1,
                col: 1,
                message: format!(
                    "a mapping file of {} bytes, more than the {MAX_MAPPING_LEN} read",
                    text.len()
                ),
            });
        }
        let file: File = toml::from_str(text).map_err(|e| {
            let at = e.span().map_or(0, |s| s.start);
            let src = crate::source::SourceFile::new("", text);
            let lc = src.line_col(at);
            MappingError {
                line: lc.line,
                col: lc.column,
                message: e.message().to_string(),
            }
        })?;
        Ok(Mapping {
            nets: file.rename.nets,
            places: file.rename.places,
            timers: file.rename.timers,
            vanished_places: file.vanished.places,
            vanished_nets: file.vanished.nets,
            vanished_timers: file.vanished.timers,
        })
    }

    /// True when it says nothing.
    pub fn is_empty(&self) -> bool {
        *self == Mapping::default()
    }
}

/// The state of the running version, as the engine holds it between two steps.
pub struct OldState<'a> {
    /// The state bits ([`Layout`] of the old project).
    pub state: &'a [u64],
    /// Each timer's deadline, if it runs (mission time, microseconds).
    pub deadlines: &'a [Option<u64>],
    /// Each net's activation arguments.
    pub net_args: &'a [Vec<Value>],
}

/// The new version's state, and what the mapping did, for people.
#[derive(Clone, Debug, PartialEq)]
pub struct Mapped {
    /// The state bits ([`Layout`] of the new project).
    pub state: Vec<u64>,
    /// Each new timer's deadline.
    pub deadlines: Vec<Option<u64>>,
    /// Each new net's activation arguments.
    pub net_args: Vec<Vec<Value>>,
    /// One line per thing carried over, renamed, dropped or added.
    pub summary: Vec<String>,
}

/// Why a reload cannot map the state: every reason, one line each.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct MapRefusal {
    /// The reasons.
    pub reasons: Vec<String>,
}

/// Checks the mapping's names against both versions: a rename or a `vanished` entry naming
/// nothing is a mistake in the file, said before anything is mapped.
fn check_names(old: &CompiledProject, new: &CompiledProject, m: &Mapping) -> Vec<String> {
    let mut out = Vec::new();
    for (a, b) in &m.nets {
        if old.net_id(a).is_none() {
            out.push(format!(
                "mapping: [rename] nets: the running version has no net `{a}`"
            ));
        }
        if new.net_id(b).is_none() {
            out.push(format!(
                "mapping: [rename] nets: the new version has no net `{b}`"
            ));
        }
    }
    for (a, b) in &m.places {
        if old.place_ref(a).is_none() {
            out.push(format!(
                "mapping: [rename] places: the running version has no place `{a}`"
            ));
        }
        if new.place_ref(b).is_none() {
            out.push(format!(
                "mapping: [rename] places: the new version has no place `{b}`"
            ));
        }
    }
    let timer = |p: &CompiledProject, n: &str| p.timers.iter().any(|t| t.name == n);
    for (a, b) in &m.timers {
        if !timer(old, a) {
            out.push(format!(
                "mapping: [rename] timers: the running version has no timer `{a}`"
            ));
        }
        if !timer(new, b) {
            out.push(format!(
                "mapping: [rename] timers: the new version has no timer `{b}`"
            ));
        }
    }
    for p in &m.vanished_places {
        if old.place_ref(p).is_none() {
            out.push(format!(
                "mapping: [vanished] places: the running version has no place `{p}`"
            ));
        }
    }
    for n in &m.vanished_nets {
        if old.net_id(n).is_none() {
            out.push(format!(
                "mapping: [vanished] nets: the running version has no net `{n}`"
            ));
        }
    }
    for t in &m.vanished_timers {
        if !timer(old, t) {
            out.push(format!(
                "mapping: [vanished] timers: the running version has no timer `{t}`"
            ));
        }
    }
    out
}

/// Maps the running version's state onto `new` (docs/semantics.md): by names, after the
/// mapping's renames. Every reason it cannot is in the refusal.
pub fn map_state(
    old: &CompiledProject,
    from: &OldState<'_>,
    new: &CompiledProject,
    mapping: &Mapping,
) -> Result<Mapped, MapRefusal> {
    let lo = Layout::new(old);
    let ln = Layout::new(new);
    let mut reasons = check_names(old, new, mapping);
    if from.state.len() != lo.words {
        reasons.push(format!(
            "the running state has {} words, the running version {}",
            from.state.len(),
            lo.words
        ));
        return Err(MapRefusal { reasons });
    }
    let mut summary = Vec::new();
    let mut s = vec![0u64; ln.words];
    let set = |s: &mut Vec<u64>, b: u32| s[(b / 64) as usize] |= 1 << (b % 64);
    if lo.is_over(from.state) {
        reasons
            .push("a catastrophic event ended the mission: there is nothing to reload into".into());
    }
    // Nets: each active one keeps its name (or takes its new one).
    let mut net_to: Vec<Option<NetId>> = vec![None; old.nets.len()];
    let mut net_args: Vec<Vec<Value>> = vec![Vec::new(); new.nets.len()];
    let mut mapped_from: Vec<bool> = vec![false; new.nets.len()];
    for (n, net) in old.nets.iter().enumerate() {
        let target = mapping.nets.get(&net.name).unwrap_or(&net.name);
        if let Some(t) = new.net_id(target) {
            mapped_from[t as usize] = true;
            net_to[n] = Some(t);
        }
        if !lo.is_active(from.state, n as NetId) {
            continue;
        }
        let Some(t) = net_to[n] else {
            if mapping.vanished_nets.contains(&net.name) {
                summary.push(format!(
                    "net {}: dropped with its tokens ([vanished] nets)",
                    net.name
                ));
            } else {
                reasons.push(format!(
                    "active net `{}` is not in the new version (rename it in [rename] nets, or list it in [vanished] nets to drop it)",
                    net.name
                ));
            }
            continue;
        };
        let nn = &new.nets[t as usize];
        if nn.params != net.params {
            reasons.push(format!(
                "active net `{}` has other parameters bound at activation in the new version ({:?}, was {:?}): its arguments cannot follow",
                net.name,
                nn.params.iter().map(|(n, t)| format!("{n}: {t}")).collect::<Vec<_>>(),
                net.params.iter().map(|(n, t)| format!("{n}: {t}")).collect::<Vec<_>>()
            ));
            continue;
        }
        let old_parent = net.parent.map(|(p, _)| old.nets[p as usize].name.clone());
        let new_parent = nn.parent.map(|(p, _)| new.nets[p as usize].name.clone());
        let renamed_parent = old_parent
            .as_ref()
            .map(|p| mapping.nets.get(p).unwrap_or(p).clone());
        if renamed_parent != new_parent {
            reasons.push(format!(
                "active net `{}` is a child of {} in the running version and of {} in the new one: its completion cannot follow",
                net.name,
                old_parent.map_or("no net".into(), |p| format!("`{p}`")),
                new_parent.map_or("no net".into(), |p| format!("`{p}`"))
            ));
            continue;
        }
        set(&mut s, ln.net_active[t as usize]);
        net_args[t as usize] = from.net_args.get(n).cloned().unwrap_or_default();
        if target != &net.name {
            summary.push(format!("net {} -> {}: active", net.name, nn.name));
        } else {
            summary.push(format!("net {}: active", net.name));
        }
    }
    // New nets of the new version's `start` begin as they would at a mission's start.
    for &n in &new.start {
        if !mapped_from[n as usize] {
            set(&mut s, ln.net_active[n as usize]);
            let net = &new.nets[n as usize];
            let initial: Vec<&str> = net
                .places
                .iter()
                .enumerate()
                .filter(|(_, p)| p.initial)
                .map(|(i, p)| {
                    set(&mut s, ln.net_base[n as usize] + i as u32);
                    p.name.as_str()
                })
                .collect();
            summary.push(format!(
                "net {}: new, in start: activated with {{{}}}",
                net.name,
                initial.join(", ")
            ));
        }
    }
    // Marked places, local then global.
    let mut place = |name: String, s: &mut Vec<u64>, reasons: &mut Vec<String>| {
        if let Some(to) = mapping.places.get(&name) {
            // A name the new version lacks was said by check_names.
            if let Some((n, r)) = new.place_ref(to) {
                if let PlaceRef::Local(_) = r {
                    if !Layout::bit(s, ln.net_active[n as usize]) {
                        reasons.push(format!(
                            "marked place `{name}` is renamed `{to}`, whose net is not active in the new state"
                        ));
                        return;
                    }
                }
                set(s, ln.place_bit(n, r));
                summary.push(format!("{name} -> {to}: marked"));
            }
            return;
        }
        if mapping.vanished_places.contains(&name) {
            summary.push(format!("{name}: token dropped ([vanished] places)"));
            return;
        }
        // Same name, in the net the old one became.
        let target = match name.strip_prefix("global.") {
            Some(g) => new
                .globals
                .iter()
                .position(|x| x.name == g)
                .map(|i| ln.global_base + i as u32),
            None => None,
        };
        let target = target.or_else(|| {
            let (n, r) = old.place_ref(&name)?;
            let PlaceRef::Local(i) = r else { return None };
            let t = net_to[n as usize]?;
            let pname = &old.nets[n as usize].places[i as usize].name;
            let k = new.nets[t as usize]
                .places
                .iter()
                .position(|p| &p.name == pname)?;
            Some(ln.net_base[t as usize] + k as u32)
        });
        match target {
            Some(b) => set(s, b),
            None => reasons.push(format!(
                "marked place `{name}` is not in the new version (rename it in [rename] places, or list it in [vanished] places to drop its token)"
            )),
        }
    };
    for (n, net) in old.nets.iter().enumerate() {
        if !lo.is_active(from.state, n as NetId) {
            continue;
        }
        // A dropped or refused net's places are said with it.
        let dropped = net_to[n].is_none() && mapping.vanished_nets.contains(&net.name);
        for (i, p) in net.places.iter().enumerate() {
            if !dropped && lo.is_marked(from.state, n as NetId, PlaceRef::Local(i as u32)) {
                place(format!("{}.{}", net.name, p.name), &mut s, &mut reasons);
            }
        }
    }
    for (g, gp) in old.globals.iter().enumerate() {
        if Layout::bit(from.state, lo.global_base + g as u32) {
            place(format!("global.{}", gp.name), &mut s, &mut reasons);
        }
    }
    for (g, gp) in new.globals.iter().enumerate() {
        let known = old.globals.iter().any(|o| o.name == gp.name)
            || mapping
                .places
                .values()
                .any(|v| v.strip_prefix("global.") == Some(&gp.name));
        if !known && gp.initial {
            set(&mut s, ln.global_base + g as u32);
            summary.push(format!(
                "global.{}: new, marked as its manifest says",
                gp.name
            ));
        } else if !known {
            summary.push(format!("global.{}: new, empty", gp.name));
        }
    }
    // Running timers keep their deadlines.
    let mut deadlines = vec![None; new.timers.len()];
    for (t, timer) in old.timers.iter().enumerate() {
        let Some(deadline) = from.deadlines.get(t).copied().flatten() else {
            continue;
        };
        let target = mapping.timers.get(&timer.name).unwrap_or(&timer.name);
        match new.timers.iter().position(|x| &x.name == target) {
            Some(k) => {
                let (was, now) = (
                    &old.events[timer.event as usize].name,
                    &new.events[new.timers[k].event as usize].name,
                );
                if was != now {
                    reasons.push(format!(
                        "running timer `{}` raises `{was}` in the running version, `{now}` in the new one: the nets waiting for it cannot follow",
                        timer.name
                    ));
                    continue;
                }
                deadlines[k] = Some(deadline);
                set(&mut s, ln.timer_base + k as u32);
                summary.push(format!(
                    "timer {}{}: running, deadline {:.3} s",
                    timer.name,
                    if target != &timer.name {
                        format!(" -> {target}")
                    } else {
                        String::new()
                    },
                    deadline as f64 / 1e6
                ));
            }
            None if mapping.vanished_timers.contains(&timer.name) => {
                summary.push(format!("timer {}: cancelled ([vanished] timers)", timer.name));
            }
            None => reasons.push(format!(
                "running timer `{}` is not in the new version (rename it in [rename] timers, or list it in [vanished] timers to cancel it)",
                timer.name
            )),
        }
    }
    if reasons.is_empty() {
        // A reload lands in a stable state: it fires nothing itself.
        for &r in &ln.immediate {
            let rule = &ln.rules[r as usize];
            let t = &new.nets[rule.net as usize].transitions[rule.transition as usize];
            let guard = t
                .guard
                .as_ref()
                .is_none_or(|g| g.holds(&[], &net_args[rule.net as usize]));
            if ln.enabled(&s, r) && guard {
                reasons.push(format!(
                    "immediate transition `{}.{}` is enabled in the mapped state: a reload must land in a stable state",
                    new.nets[rule.net as usize].name, t.name
                ));
            }
        }
    }
    if !reasons.is_empty() {
        return Err(MapRefusal { reasons });
    }
    summary.push(format!(
        "mapped state: {}",
        ln.describe_state(new, &s).join(" ")
    ));
    Ok(Mapped {
        state: s,
        deadlines,
        net_args,
        summary,
    })
}

/// Why a reload is refused after its mapping: a finding of the verification from the mapped
/// state (what, and the shortest trace from that state), or a verification that could not
/// finish.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct Finding {
    /// What the verifier found, in words.
    pub what: String,
    /// The events from the mapped state to it (empty: the mapped state itself).
    pub trace: Vec<String>,
}

/// The first finding of `report` that refuses a reload (docs/semantics.md): an unsafe place,
/// a cycle of immediate transitions, a cascade of produced events that does not settle, an
/// unintended dead marking, a broken invariant.
pub fn refusing_finding(report: &crate::verify::Report) -> Option<Finding> {
    if let Some(u) = report.unsafe_places.first() {
        return Some(Finding {
            what: format!(
                "unsafe place: `{}` would put a second token in `{}`",
                u.transition, u.place
            ),
            trace: u.trace.clone(),
        });
    }
    if let Some(l) = report.livelocks.first() {
        return Some(Finding {
            what: format!(
                "livelock: immediate transitions fire forever ({})",
                l.transitions.join(" -> ")
            ),
            trace: l.trace.clone(),
        });
    }
    if let Some(c) = report.cascades.first() {
        return Some(Finding {
            what: format!(
                "livelock: events produced at one instant do not settle ({}; {})",
                c.events.join(" -> "),
                c.transitions.join(", ")
            ),
            trace: c.trace.clone(),
        });
    }
    if let Some(d) = report.dead_markings.iter().find(|d| !d.intended) {
        return Some(Finding {
            what: format!(
                "unintended dead marking: nothing can fire any more in [{}]",
                d.marking.join(", ")
            ),
            trace: d.trace.clone(),
        });
    }
    if let Some(i) = report.invariant_violations.first() {
        return Some(Finding {
            what: format!(
                "invariant `{}` broken in [{}]",
                i.invariant,
                i.marking.join(", ")
            ),
            trace: i.trace.clone(),
        });
    }
    None
}

/// Verifies `new` from the mapped state: `Ok` with the states explored, or the finding that
/// refuses the reload (a verification that cannot finish refuses it too, said as the finding).
pub fn verify_mapped(
    new: &CompiledProject,
    mapped: &Mapped,
    max_states: Option<u64>,
) -> Result<u64, Finding> {
    let opts = crate::verify::VerifyOptions {
        max_states,
        ..Default::default()
    };
    match crate::verify::verify_from(new, &mapped.state, opts) {
        Ok(report) => match refusing_finding(&report) {
            Some(f) => Err(f),
            None => Ok(report.states),
        },
        Err(e) => Err(Finding {
            what: format!("the verification from the mapped state did not finish: {e}"),
            trace: Vec::new(),
        }),
    }
}

/// A content hash of a project's source files (`(path, text)`, the manifest first, then the
/// net files in the manifest's order), as 16 hex digits: what `petrel reload` sends and what
/// the player checks after reading the files, and the name of the copy kept beside the
/// journal. FNV-1a over 64 bits: it tells files that changed between the request and the
/// reading, not a forger (who could write the files anyway).
pub fn source_digest<'a>(files: impl IntoIterator<Item = (&'a str, &'a str)>) -> String {
    let mut h: u64 = 0xcbf2_9ce4_8422_2325;
    let mut eat = |bytes: &[u8]| {
        for b in bytes {
            h ^= u64::from(*b);
            h = h.wrapping_mul(0x0100_0000_01b3);
        }
    };
    for (path, text) in files {
        // Lengths first, so that no two lists of files give one byte stream.
        eat(&(path.len() as u64).to_le_bytes());
        eat(path.as_bytes());
        eat(&(text.len() as u64).to_le_bytes());
        eat(text.as_bytes());
    }
    format!("{h:016x}")
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::semantics::{NoEffects, Scratch, Semantics};

    const MANIFEST: &str = "[project]\nname = \"p\"\nfiles = [\"a.pn\"]\nstart = [\"A\"]\n\n[globals]\ng = 1\n\n[events]\ngo = { category = \"nominal\" }\nback = { category = \"nominal\" }\ntick = { category = \"nominal\" }\n\n[timers]\nt = { event = \"tick\" }\n";
    const NET: &str = "net A {\n    place p = 1\n    place q\n    transition go on go: p -> q {\n        start t after 10s\n    }\n    transition back on back: q -> p\n}\n";

    fn compile(manifest: &str, net: &str) -> CompiledProject {
        let (_, c, d, _) = crate::project::from_sources(manifest, &[("a.pn", net)]);
        assert!(!d.has_errors(), "{d:?}");
        c.expect("compiles")
    }

    /// The running project after `go` (A.q marked, timer t running at 10 s).
    fn running() -> (CompiledProject, Vec<u64>, Vec<Option<u64>>) {
        let p = compile(MANIFEST, NET);
        let sem = Semantics::new(&p);
        let mut scratch = Scratch::default();
        let mut s = sem.initial(&mut NoEffects, &mut scratch);
        let go = p.event_id("go").unwrap();
        sem.process_event(&mut s, go, None, &mut NoEffects, &mut scratch);
        (p, s, vec![Some(10_000_000)])
    }

    fn map(new: &CompiledProject, mapping: &str) -> Result<Mapped, MapRefusal> {
        let (old, s, d) = running();
        let args = vec![Vec::new(); old.nets.len()];
        let from = OldState {
            state: &s,
            deadlines: &d,
            net_args: &args,
        };
        map_state(
            &old,
            &from,
            new,
            &Mapping::parse(mapping).expect("mapping reads"),
        )
    }

    fn described(p: &CompiledProject, m: &Mapped) -> Vec<String> {
        Layout::new(p).describe_state(p, &m.state)
    }

    #[test]
    fn the_same_version_maps_to_the_same_state() {
        let (old, s, _) = running();
        let m = map(&old, "").unwrap();
        assert_eq!(m.state, s);
        assert_eq!(m.deadlines, vec![Some(10_000_000)]);
        assert_eq!(
            described(&old, &m),
            vec!["A{q}", "global.g", "timer t running"]
        );
    }

    #[test]
    fn a_marked_place_that_vanishes_is_refused_unless_the_mapping_drops_it() {
        let net = NET
            .replace("place q\n", "place r\n")
            .replace("-> q", "-> r")
            .replace("q ->", "r ->");
        let new = compile(MANIFEST, &net);
        let r = map(&new, "").unwrap_err();
        assert_eq!(r.reasons.len(), 1, "{r:?}");
        assert!(
            r.reasons[0].contains("marked place `A.q` is not in the new version"),
            "{r:?}"
        );
        // Dropped: A stays active with nothing marked.
        let m = map(&new, "[vanished]\nplaces = [\"A.q\"]\n").unwrap();
        assert_eq!(
            described(&new, &m),
            vec!["A{}", "global.g", "timer t running"]
        );
        assert!(
            m.summary.iter().any(|l| l.contains("A.q: token dropped")),
            "{:?}",
            m.summary
        );
        // Renamed: the token follows.
        let m = map(&new, "[rename]\nplaces = { \"A.q\" = \"A.r\" }\n").unwrap();
        assert_eq!(
            described(&new, &m),
            vec!["A{r}", "global.g", "timer t running"]
        );
    }

    #[test]
    fn an_active_net_that_vanishes_is_refused_unless_dropped_or_renamed() {
        let renamed = compile(
            &MANIFEST.replace("[\"A\"]", "[\"B\"]"),
            &NET.replace("net A", "net B"),
        );
        let r = map(&renamed, "").unwrap_err();
        assert!(
            r.reasons
                .iter()
                .any(|x| x.contains("active net `A` is not in the new version")),
            "{r:?}"
        );
        let m = map(&renamed, "[rename]\nnets = { A = \"B\" }\n").unwrap();
        assert_eq!(
            described(&renamed, &m),
            vec!["B{q}", "global.g", "timer t running"]
        );
        // Dropped: B is new and in start, so it begins at its initial marking.
        let m = map(&renamed, "[vanished]\nnets = [\"A\"]\n").unwrap();
        assert_eq!(
            described(&renamed, &m),
            vec!["B{p}", "global.g", "timer t running"]
        );
        assert!(
            m.summary.iter().any(|l| l.contains("net B: new, in start")),
            "{:?}",
            m.summary
        );
    }

    #[test]
    fn a_running_timer_that_vanishes_or_changes_its_event_is_refused() {
        let manifest = MANIFEST.replace("[timers]\nt = { event = \"tick\" }\n", "");
        let net = NET.replace("        start t after 10s\n", "");
        let new = compile(&manifest, &net);
        let r = map(&new, "").unwrap_err();
        assert!(
            r.reasons
                .iter()
                .any(|x| x.contains("running timer `t` is not in the new version")),
            "{r:?}"
        );
        let m = map(&new, "[vanished]\ntimers = [\"t\"]\n").unwrap();
        assert_eq!(m.deadlines, Vec::<Option<u64>>::new());
        let other = compile(
            &MANIFEST.replace("event = \"tick\"", "event = \"back\""),
            NET,
        );
        let r = map(&other, "").unwrap_err();
        assert!(
            r.reasons
                .iter()
                .any(|x| x.contains("raises `tick` in the running version, `back` in the new one")),
            "{r:?}"
        );
    }

    #[test]
    fn new_start_nets_and_global_places_begin_as_declared() {
        let manifest = MANIFEST
            .replace("[\"A\"]", "[\"A\", \"C\"]")
            .replace("g = 1\n", "g = 1\nh = 1\nk = 0\n");
        let net = format!("{NET}net C {{\n    place c = 1\n    transition cc on go: c -> c\n}}\n");
        let new = compile(&manifest, &net);
        let m = map(&new, "").unwrap();
        assert_eq!(
            described(&new, &m),
            vec!["A{q}", "C{c}", "global.g", "global.h", "timer t running"]
        );
    }

    #[test]
    fn changed_parameters_and_enabled_immediate_transitions_are_refused() {
        let with_b =
            |params: &str| {
                compile(
                    MANIFEST,
                    &format!(
                    "{}net B({params}) {{\n    place b = 1\n    transition u on back: b -> b\n}}\n",
                    NET.replace("start t after 10s", "start t after 10s\n        activate B(3)")
                ),
                )
            };
        let (old, new) = (with_b("x: int"), with_b("y: int"));
        let sem = Semantics::new(&old);
        let mut scratch = Scratch::default();
        let mut s = sem.initial(&mut NoEffects, &mut scratch);
        sem.process_event(
            &mut s,
            old.event_id("go").unwrap(),
            None,
            &mut NoEffects,
            &mut scratch,
        );
        let args = vec![Vec::new(), vec![Value::Int(3)]];
        let from = OldState {
            state: &s,
            deadlines: &[Some(1)],
            net_args: &args,
        };
        let r = map_state(&old, &from, &new, &Mapping::default()).unwrap_err();
        assert!(
            r.reasons
                .iter()
                .any(|x| x.contains("active net `B` has other parameters")),
            "{r:?}"
        );
        // The same parameters: the arguments follow.
        let m = map_state(&old, &from, &old, &Mapping::default()).unwrap();
        assert_eq!(m.net_args[1], vec![Value::Int(3)]);
        let immediate = compile(
            MANIFEST,
            &NET.replace(
                "    transition back",
                "    transition auto: q -> p\n    transition back",
            ),
        );
        let r = map(&immediate, "").unwrap_err();
        assert!(
            r.reasons
                .iter()
                .any(|x| x.contains("immediate transition `A.auto` is enabled")),
            "{r:?}"
        );
    }

    #[test]
    fn the_mapping_file_says_where_it_is_wrong() {
        let e = Mapping::parse("[rename]\nnets = { A = 3 }\n").unwrap_err();
        assert_eq!((e.line, e.col), (2, 14), "{e}");
        let e = Mapping::parse("[rename]\nnet = {}\n").unwrap_err();
        assert_eq!(e.line, 2, "{e}");
        assert!(e.message.contains("unknown field"), "{e}");
        let (old, _, _) = running();
        let r = map(
            &old,
            "[rename]\nplaces = { \"A.x\" = \"A.q\" }\n[vanished]\nnets = [\"Z\"]\n",
        )
        .unwrap_err();
        assert!(
            r.reasons
                .iter()
                .any(|x| x.contains("running version has no place `A.x`")),
            "{r:?}"
        );
        assert!(
            r.reasons
                .iter()
                .any(|x| x.contains("running version has no net `Z`")),
            "{r:?}"
        );
    }

    #[test]
    fn the_source_digest_tells_files_apart() {
        let a = source_digest([("petrel.toml", "x"), ("a.pn", "y")]);
        assert_eq!(a, source_digest([("petrel.toml", "x"), ("a.pn", "y")]));
        assert_ne!(a, source_digest([("petrel.toml", "xa"), (".pn", "y")]));
        assert_eq!(a.len(), 16);
    }

    #[test]
    fn verification_from_the_mapped_state_finds_what_the_start_does_not() {
        // `again` would put a second token in q, but only from a state where q is marked and
        // p is too: unreachable from the start, reached by mapping a version where both are.
        let net = NET.replace(
            "    transition back",
            "    transition again on back: p -> q\n    transition back",
        );
        let new = compile(MANIFEST, &net);
        let from_start = crate::verify::verify(&new, Default::default()).unwrap();
        assert!(from_start.safe, "{from_start:?}");
        let two = compile(
            MANIFEST,
            "net A {\n    place p = 1\n    place q = 1\n    transition go on go: p -> p\n    transition back on back: q -> q\n    transition tick on tick: p -> p\n}\n",
        );
        let sem = Semantics::new(&two);
        let s = sem.initial(&mut NoEffects, &mut Scratch::default());
        let args = vec![Vec::new()];
        let m = map_state(
            &two,
            &OldState {
                state: &s,
                deadlines: &[None],
                net_args: &args,
            },
            &new,
            &Mapping::default(),
        )
        .unwrap();
        let f = verify_mapped(&new, &m, None).unwrap_err();
        assert_eq!(
            f.what,
            "unsafe place: `A.go` would put a second token in `A.q`"
        );
        assert_eq!(f.trace, vec!["go"]);
        let r = crate::verify::verify_from(&new, &m.state, Default::default()).unwrap();
        assert!(!r.safe);
        assert_eq!(r.unsafe_places[0].place, "A.q");
        assert_eq!(r.unsafe_places[0].trace, vec!["go"]);
    }
}
