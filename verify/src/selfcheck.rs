//! Cross-checks for tests: the findings do not depend on whether the graph kept its edges or
//! replays them ([`check_replay`]), and the transition cache builds the graph built without it
//! ([`check_cache`]).

use crate::{env, explore, EdgeMemory, VerifyOptions};
use petrel_nets::compiled::CompiledProject;
use petrel_nets::semantics::Semantics;
use std::time::Instant;

/// A cross-check for tests (docs/verification.md, "The state store"): explores `project` in
/// full (no partial-order reduction, whatever `opts` says), keeping every edge, then recomputes
/// each state's edges as the analyses do when the graph does not keep them, and compares.
/// Returns how many edges were compared, or the first state whose recomputed edges differ from
/// the explored ones.
pub fn check_replay(project: &CompiledProject, mut opts: VerifyOptions) -> Result<u64, String> {
    opts.no_reduction = true;
    opts.edges = EdgeMemory::Keep;
    if opts.only_net.is_some() {
        return Err("--net: the environment's moves are not replayed".into());
    }
    let sem = Semantics::new(project);
    let env = env::Env::new(project, sem.layout.words);
    let (g, mut replay) =
        explore::explore(project, &sem, &env, &[], &mut opts, Instant::now(), None)
            .map_err(|e| e.to_string())?;
    let (mut kept, mut replayed) = (Vec::new(), Vec::new());
    let mut compared = 0u64;
    for i in 0..g.states.len() as u32 {
        kept.clear();
        g.kept_edges(i, &mut kept);
        replayed.clear();
        replay.edges(&g, i, &mut replayed);
        if kept != replayed {
            return Err(format!(
                "state {i}: explored edges {kept:?}, replayed {replayed:?}"
            ));
        }
        compared += kept.len() as u64;
    }
    if compared != g.edge_count() as u64 || !g.edges_kept() {
        return Err(format!("{compared} edges compared of {}", g.edge_count()));
    }
    Ok(compared)
}

/// A cross-check for tests (docs/verification.md, "The transition cache"): explores `project`
/// in full (no partial-order reduction, edges kept, whatever `opts` says) with the transition
/// cache and without it, and compares the two graphs: the states in order, each state's
/// parent and label (the traces), its edges in order, the labels, fired sets and step kinds,
/// and what the exploration found (dead states, unsafe places, loops of immediate
/// transitions, conflicts, transitions fired, nets active); then the edges each recomputes
/// for the analyses. Returns how many components' moves the cache gave (0 when it did not
/// apply), or the first difference.
pub fn check_cache(project: &CompiledProject, mut opts: VerifyOptions) -> Result<u64, String> {
    opts.no_reduction = true;
    opts.edges = EdgeMemory::Keep;
    if opts.only_net.is_some() {
        return Err("--net: no transition cache".into());
    }
    let sem = Semantics::new(project);
    let env = env::Env::new(project, sem.layout.words);
    let mut run = |no_cache: bool| {
        opts.no_cache = no_cache;
        explore::explore(project, &sem, &env, &[], &mut opts, Instant::now(), None)
            .map_err(|e| e.to_string())
    };
    let (cached, mut cached_replay) = run(false)?;
    let (plain, mut plain_replay) = run(true)?;
    let (a, b) = (&cached, &plain);
    if a.states.len() != b.states.len() {
        return Err(format!(
            "{} states with the cache, {} without",
            a.states.len(),
            b.states.len()
        ));
    }
    let (mut ea, mut eb) = (Vec::new(), Vec::new());
    for i in 0..a.states.len() as u32 {
        if a.states[i as usize] != b.states[i as usize] || a.parent(i) != b.parent(i) {
            return Err(format!("state {i} or its parent differ"));
        }
        ea.clear();
        eb.clear();
        a.kept_edges(i, &mut ea);
        b.kept_edges(i, &mut eb);
        if ea != eb {
            return Err(format!(
                "state {i}: edges {ea:?} with the cache, {eb:?} without"
            ));
        }
        // What the analyses recompute when they do not keep the edges.
        ea.clear();
        eb.clear();
        cached_replay.edges(a, i, &mut ea);
        plain_replay.edges(b, i, &mut eb);
        if ea != eb {
            return Err(format!(
                "state {i}: replayed edges {ea:?} with the cache, {eb:?} without"
            ));
        }
    }
    let labels = |g: &explore::Graph| format!("{:?}", g.labels);
    let same = labels(a) == labels(b)
        && a.fired_sets == b.fired_sets
        && a.steps() == b.steps()
        && a.dead == b.dead
        && a.unsafe_places == b.unsafe_places
        && a.livelocks == b.livelocks
        && a.conflicts == b.conflicts
        && a.ever_fired == b.ever_fired
        && a.ever_active == b.ever_active
        && a.max_tokens_per_marking == b.max_tokens_per_marking;
    if !same {
        return Err("the labels, step kinds or findings differ".into());
    }
    if b.cache_hits != 0 {
        return Err("the cache was used when it was turned off".into());
    }
    Ok(a.cache_hits)
}
