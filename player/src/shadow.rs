//! The ground-station shadow (`petrel play --shadow`): a copy of the supervision that follows
//! the vehicle's player step by step, runs no action, and raises an alarm the moment its marking
//! differs from the vehicle's (section 3.2.4 of the ProCoSA paper).
//!
//! It listens to the vehicle's marking deltas: each names the event the vehicle processed and
//! the places it marked and unmarked. The shadow processes the same event on its own engine
//! (events steer firings by their names; parameters only reach actions, which the shadow does
//! not run) and compares the two markings. On a difference it raises the alarm, then takes the
//! vehicle's marking again so that later alarms are about later steps.
//!
//! It follows reloads (`petrel reload`): the player answers every reload request to every
//! listener, and publishes a snapshot of the new state after its answer. On an accepted reload
//! the shadow reads the new version from the directory the answer names (the ground station
//! must see the same files: the same computer, or the same path on a shared disk) and checks
//! its content hash; then it follows the snapshot with the new version. When it cannot (no
//! such directory, other files, a version that does not check), it raises the alarm and
//! follows no more.

use crate::engine::{Engine, NullSink};
use crate::runtime::{PlayError, PlayOptions};
use petrel_ipc::{Participant, Reactor, Role, Vehicle};
use petrel_nets::compiled::{CompiledProject, PlaceRef};
use petrel_nets::semantics::Layout;
use std::collections::BTreeSet;
use std::time::{Duration, Instant};
use tracing::{error, info, warn};

/// What a shadow run saw.
#[derive(Clone, Debug, Default)]
pub struct ShadowReport {
    /// Vehicle steps followed.
    pub steps: u64,
    /// Divergence alarms raised (a reload the shadow cannot follow is one).
    pub alarms: u64,
    /// Reloads of the vehicle's project followed.
    pub reloads: u64,
}

/// The vehicle's marking as the shadow rebuilds it from the deltas.
#[derive(Default)]
struct Mirror {
    active: BTreeSet<String>,
    marked: BTreeSet<String>,
}

impl Mirror {
    /// The state bits of this marking, for the shadow's engine.
    fn state(&self, project: &CompiledProject, layout: &Layout) -> Vec<u64> {
        let mut s = vec![0u64; layout.words];
        let mut set = |b: u32| s[(b / 64) as usize] |= 1 << (b % 64);
        for (n, net) in project.nets.iter().enumerate() {
            if self.active.contains(&net.name) {
                set(layout.net_active[n]);
            }
            for (i, p) in net.places.iter().enumerate() {
                if self.marked.contains(&format!("{}.{}", net.name, p.name)) {
                    set(layout.place_bit(n as u32, PlaceRef::Local(i as u32)));
                }
            }
        }
        for (g, gp) in project.globals.iter().enumerate() {
            if self.marked.contains(&format!("global.{}", gp.name)) {
                set(layout.global_base + g as u32);
            }
        }
        s
    }
}

/// The shadow engine's marking, as the vehicle names it.
fn shadow_marking(engine: &Engine) -> BTreeSet<String> {
    let mut out = BTreeSet::new();
    for (net, places) in engine.marking() {
        for p in places {
            out.insert(format!("{net}.{p}"));
        }
    }
    out
}

/// Takes the player's reload answers: an accepted reload (not a dry run) swaps the shadow's
/// project for the new version, read from the directory the answer names; one it cannot read
/// raises the alarm, and the shadow follows no more (`lost`). True when it swapped.
fn follow_reloads<'p>(
    answers: &petrel_ipc::ReloadAnswerSubscriber,
    project: &mut &'p CompiledProject,
    engine: &mut Engine<'p>,
    lost: &mut bool,
    report: &mut ShadowReport,
) -> bool {
    let mut swapped = false;
    let mut accepted = Vec::new();
    let drained = answers.drain(|r| match r {
        Ok(rcv) if rcv.origin.as_str() == "player" && rcv.msg.accepted && !rcv.msg.dry_run => {
            accepted.push(rcv.msg)
        }
        Ok(_) => {}
        Err(e) => warn!(error = %e, "a reload answer could not be read"),
    });
    if let Err(e) = drained {
        warn!(error = %e, "reload answers could not be read");
    }
    for a in accepted {
        if *lost {
            return swapped;
        }
        match crate::reload::version::load_candidate(
            std::path::Path::new(&a.dir),
            &a.source_hash,
            "",
        ) {
            Ok(c) => {
                let new = crate::reload::version::leak(c.project);
                *project = new;
                *engine = Engine::new(new);
                engine.start(0, &mut NullSink);
                report.reloads += 1;
                swapped = true;
                info!(hash = %a.source_hash, dir = %a.dir, "the vehicle reloaded its project: the shadow follows the new version");
            }
            Err(reasons) => {
                *lost = true;
                report.alarms += 1;
                error!(hash = %a.source_hash, dir = %a.dir, ?reasons, "ALARM: the vehicle reloaded its project and the shadow cannot read the new version: it follows no more");
                eprintln!(
                    "ALARM the vehicle reloaded version {} from {}; the shadow cannot follow: {}",
                    a.source_hash,
                    a.dir,
                    reasons.join("; ")
                );
            }
        }
    }
    swapped
}

/// Runs the shadow until SIGINT/SIGTERM (or `run_for`).
pub fn shadow(project: &CompiledProject, opts: &PlayOptions) -> Result<ShadowReport, PlayError> {
    let vehicle = Vehicle::new(&opts.vehicle).map_err(|e| PlayError::Vehicle(e.to_string()))?;
    let role = Role::tool(&format!("shadow{}", std::process::id()))
        .map_err(|e| PlayError::Setup(e.to_string()))?;
    let me = Participant::join(&vehicle, role).map_err(|e| PlayError::Setup(e.to_string()))?;
    let deltas = me
        .marking_subscriber()
        .map_err(|e| PlayError::Setup(e.to_string()))?;
    let beats = me
        .heartbeat_subscriber()
        .map_err(|e| PlayError::Setup(e.to_string()))?;
    let answers = me
        .reload_answer_subscriber()
        .map_err(|e| PlayError::Setup(e.to_string()))?;
    let reactor = Reactor::new(opts.wait).map_err(|e| PlayError::Setup(e.to_string()))?;
    let mut project: &CompiledProject = project;
    let mut lost = false;
    let mut engine = Engine::new(project);
    engine.start(0, &mut NullSink);
    let mut mirror = Mirror::default();
    let mut synced = false;
    let mut report = ShadowReport::default();
    let t0 = Instant::now();
    info!(vehicle = %opts.vehicle, "shadow started: following the vehicle's player");
    loop {
        if let Some(limit) = opts.run_for {
            if t0.elapsed() >= limit {
                break;
            }
        }
        // A vehicle already flying: take its marking from its heartbeat status.
        if !synced {
            let drained = beats.drain(|r| {
                let Ok(rcv) = r else { return };
                if rcv.origin.as_str() != "player" || synced {
                    return;
                }
                let doc: serde_json::Value =
                    serde_json::from_str(&rcv.msg.status).unwrap_or_default();
                // A status too large for a heartbeat leaves the marking out: not a marking.
                if doc["marking_omitted"] == true {
                    return;
                }
                if let Some(m) = doc["marking"].as_object() {
                    for (net, places) in m {
                        if net != "global" {
                            mirror.active.insert(net.clone());
                        }
                        for p in places.as_array().into_iter().flatten() {
                            if let Some(p) = p.as_str() {
                                mirror.marked.insert(format!("{net}.{p}"));
                            }
                        }
                    }
                    let s = mirror.state(project, engine.layout());
                    engine.set_state(&s);
                    synced = true;
                    info!("shadow synchronised on the vehicle's status");
                }
            });
            if let Err(e) = drained {
                warn!(error = %e, "the vehicle's heartbeats could not be read");
            }
        }
        let ready = reactor
            .wait(&[&deltas], Some(Duration::from_millis(50)))
            .map_err(|e| PlayError::Setup(e.to_string()))?;
        if ready.termination_requested() {
            break;
        }
        let drained = deltas.drain(|r| {
            // A reload answered before this delta was published is in its buffer by now.
            if follow_reloads(&answers, &mut project, &mut engine, &mut lost, &mut report) {
                // Follow again from the snapshot the player publishes after its answer.
                synced = false;
            }
            if lost {
                return;
            }
            let msg = match r {
                Ok(rcv) if rcv.origin.as_str() == "player" => rcv.msg,
                Ok(_) => return,
                Err(e) => {
                    warn!(error = %e, "a marking delta could not be read");
                    return;
                }
            };
            if msg.snapshot {
                mirror = Mirror::default();
                mirror.marked.extend(msg.marked.iter().cloned());
                mirror.active.extend(msg.activated.iter().cloned());
                // A snapshot marks only places; a net with a marked place is active.
                for p in &msg.marked {
                    if let Some((net, _)) = p.split_once('.') {
                        if net != "global" {
                            mirror.active.insert(net.to_string());
                        }
                    }
                }
                let s = mirror.state(project, engine.layout());
                engine.set_state(&s);
                synced = true;
                return;
            }
            for n in &msg.activated {
                mirror.active.insert(n.clone());
            }
            for n in &msg.deactivated {
                mirror.active.remove(n);
            }
            for p in &msg.unmarked {
                mirror.marked.remove(p);
            }
            mirror.marked.extend(msg.marked.iter().cloned());
            if !synced {
                return;
            }
            let Some(event) = msg.event.as_deref() else {
                return;
            };
            report.steps += 1;
            let ours = match project.event_id(event) {
                Some(e) => {
                    engine.follow(e, &mut NullSink);
                    shadow_marking(&engine)
                }
                None => {
                    error!(event, "ALARM: the vehicle processed an event this project does not declare");
                    report.alarms += 1;
                    BTreeSet::new()
                }
            };
            if ours != mirror.marked {
                report.alarms += 1;
                let only_vehicle: Vec<&String> = mirror.marked.difference(&ours).collect();
                let only_shadow: Vec<&String> = ours.difference(&mirror.marked).collect();
                error!(
                    step = msg.step,
                    event,
                    ?only_vehicle,
                    ?only_shadow,
                    "ALARM: the shadow's marking differs from the vehicle's"
                );
                eprintln!(
                    "ALARM step {} (event {event}): only in the vehicle: [{}]; only in the shadow: [{}]",
                    msg.step,
                    only_vehicle.iter().map(|s| s.as_str()).collect::<Vec<_>>().join(", "),
                    only_shadow.iter().map(|s| s.as_str()).collect::<Vec<_>>().join(", ")
                );
                // Follow the vehicle again, so the next alarm is about the next difference.
                let s = mirror.state(project, engine.layout());
                engine.set_state(&s);
            }
        });
        if let Err(e) = drained {
            warn!(error = %e, "marking deltas could not be read");
        }
    }
    Ok(report)
}
