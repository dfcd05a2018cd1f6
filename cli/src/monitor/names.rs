//! The names the player uses (`NET.place`, `NET.CHILD.done`, `NET.transition`) turned into the
//! node ids of the drawing (`NET.place`, `NET.done.CHILD`, `NET.t.transition`:
//! `petrel_nets::dot`), and what the page needs to know of the project.

use petrel_nets::compiled::CompiledProject;
use petrel_nets::model::Category;
use petrel_value::Value;
use serde_json::{json, Value as Json};
use std::collections::BTreeSet;

/// The project as the page sees it.
pub struct Names {
    /// Each event's category, by event name.
    categories: std::collections::HashMap<String, &'static str>,
    /// The page's model of the project (`/api/model`).
    pub model: Json,
}

/// A category as the manifest writes it.
fn category_name(c: Category) -> &'static str {
    c.keyword()
}

impl Names {
    /// The names of `project`.
    pub fn new(project: &CompiledProject) -> Self {
        let categories = project
            .events
            .iter()
            .map(|e| (e.name.clone(), category_name(e.category)))
            .collect();
        let nets: Vec<Json> = project.nets.iter().map(|n| net_json(project, n)).collect();
        let events: Vec<Json> = project
            .events
            .iter()
            .map(|e| {
                json!({
                    "name": e.name,
                    "category": category_name(e.category),
                    "internal": e.internal,
                    "params": e.params.iter().map(|(n, t)| format!("{n}: {t}")).collect::<Vec<_>>(),
                })
            })
            .collect();
        let programs: Vec<&str> = project.programs.iter().map(|p| p.name.as_str()).collect();
        let model = json!({
            "project": project.name,
            "nets": nets,
            "globals": project.globals.iter().map(|g| format!("global.{}", g.name)).collect::<Vec<_>>(),
            "events": events,
            "programs": programs,
        });
        Names { categories, model }
    }

    /// The category of event `name` (`?` for a name the project does not declare).
    pub fn category(&self, name: &str) -> &'static str {
        self.categories.get(name).copied().unwrap_or("?")
    }

    /// One step as the page reads it.
    #[allow(clippy::too_many_arguments)]
    pub fn step_json(
        &self,
        step: u64,
        time_us: u64,
        event: Option<&str>,
        params: &[Value],
        fired: &[String],
        actions: &[String],
        marked: &[String],
        unmarked: &[String],
        activated: &[String],
        deactivated: &[String],
    ) -> Json {
        json!({
            "type": "step",
            "step": step,
            "time": time_us as f64 / 1e6,
            "event": event,
            "category": event.map(|e| self.category(e)),
            "params": params.iter().map(Value::literal).collect::<Vec<_>>(),
            "fired": fired.iter().map(|t| transition_id(t)).collect::<Vec<_>>(),
            "actions": actions,
            "marked": marked.iter().map(|p| place_id(p)).collect::<Vec<_>>(),
            "unmarked": unmarked.iter().map(|p| place_id(p)).collect::<Vec<_>>(),
            "activated": activated,
            "deactivated": deactivated,
        })
    }
}

/// What the page knows of net `n`: its tree, its places (and which of them no transition of it
/// takes: a net whose marked places are all such has ended), its transitions' input places
/// and emptiness tests (to tell a net that waits from one that can fire), all as the
/// drawing's ids.
fn net_json(project: &CompiledProject, n: &petrel_nets::compiled::Net) -> Json {
    use petrel_nets::compiled::PlaceRef;
    let id = |r: &PlaceRef| match *r {
        PlaceRef::Local(i) => place_id(&format!("{}.{}", n.name, n.places[i as usize].name)),
        PlaceRef::Global(g) => format!("global.{}", project.globals[g as usize].name),
    };
    let taken: BTreeSet<String> = n
        .transitions
        .iter()
        .flat_map(|t| t.inputs.iter().map(id))
        .collect();
    let places: Vec<String> = n
        .places
        .iter()
        .map(|p| place_id(&format!("{}.{}", n.name, p.name)))
        .collect();
    let terminal: Vec<&String> = places.iter().filter(|p| !taken.contains(*p)).collect();
    let globals: BTreeSet<String> = n
        .transitions
        .iter()
        .flat_map(|t| t.inputs.iter().chain(&t.empty).chain(&t.outputs))
        .filter(|r| matches!(r, PlaceRef::Global(_)))
        .map(id)
        .collect();
    let transitions: Vec<Json> = n
        .transitions
        .iter()
        .map(|t| {
            json!({
                "id": format!("{}.t.{}", n.name, t.name),
                "in": t.inputs.iter().map(id).collect::<Vec<_>>(),
                "empty": t.empty.iter().map(id).collect::<Vec<_>>(),
                "event": t.event.map(|e| project.events[e as usize].name.clone()),
            })
        })
        .collect();
    json!({
        "name": n.name,
        "template": n.template,
        "parent": n.parent.map(|(p, _)| project.nets[p as usize].name.clone()),
        "children": n.children.iter().map(|&c| project.nets[c as usize].name.clone()).collect::<Vec<_>>(),
        "places": places,
        "terminal": terminal,
        "globals": globals,
        "transitions": transitions,
    })
}

/// The drawing's id of place `name` as the player names it: `NET.place` and `global.place`
/// are the same; a completion place `NET.CHILD.done` is `NET.done.CHILD`.
pub fn place_id(name: &str) -> String {
    match name.split_once('.') {
        Some((net, place)) if net != "global" => match place.strip_suffix(".done") {
            Some(child) => format!("{net}.done.{child}"),
            None => name.to_string(),
        },
        _ => name.to_string(),
    }
}

/// The drawing's id of transition `NET.transition`: `NET.t.transition`.
pub fn transition_id(name: &str) -> String {
    match name.split_once('.') {
        Some((net, t)) => format!("{net}.t.{t}"),
        None => name.to_string(),
    }
}

/// The marking of a status JSON (`{"NET": ["place", ...], "global": [...]}`) as the drawing's
/// place ids, and the active nets; `None` when the status left the marking out.
pub fn status_marking(doc: &Json) -> Option<(BTreeSet<String>, BTreeSet<String>)> {
    if doc["marking_omitted"] == true {
        return None;
    }
    let m = doc["marking"].as_object()?;
    let mut marked = BTreeSet::new();
    let mut active = BTreeSet::new();
    for (net, places) in m {
        if net != "global" {
            active.insert(net.clone());
        }
        for p in places.as_array().into_iter().flatten() {
            if let Some(p) = p.as_str() {
                marked.insert(format!("{net}.{p}"));
            }
        }
    }
    Some((marked, active))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn ids_follow_the_drawing() {
        assert_eq!(place_id("MISSION.ready"), "MISSION.ready");
        assert_eq!(place_id("global.in_flight"), "global.in_flight");
        assert_eq!(place_id("ROBOT.MOVE.done"), "ROBOT.done.MOVE");
        assert_eq!(place_id("R1/MOVE.p"), "R1/MOVE.p");
        assert_eq!(transition_id("MISSION.roll"), "MISSION.t.roll");
        assert_eq!(transition_id("R1/MOVE.go"), "R1/MOVE.t.go");
    }

    #[test]
    fn a_status_gives_its_marking() {
        let doc: Json =
            serde_json::from_str(r#"{"marking": {"MISSION": ["ready"], "global": ["on_ground"]}}"#)
                .unwrap();
        let (marked, active) = status_marking(&doc).unwrap();
        assert_eq!(
            marked.into_iter().collect::<Vec<_>>(),
            ["MISSION.ready", "global.on_ground"]
        );
        assert_eq!(active.into_iter().collect::<Vec<_>>(), ["MISSION"]);
        let omitted: Json =
            serde_json::from_str(r#"{"marking": {}, "marking_omitted": true}"#).unwrap();
        assert!(status_marking(&omitted).is_none());
    }
}
