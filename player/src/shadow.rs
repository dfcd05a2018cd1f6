//! The ground-station shadow (`petrel play --shadow`): a copy of the supervision that follows
//! the vehicle's player step by step, runs no action, and raises an alarm the moment its marking
//! differs from the vehicle's (section 3.2.4 of the ProCoSA paper).
//!
//! It listens to the vehicle's marking deltas: each names the event the vehicle processed and
//! the places it marked and unmarked. The shadow processes the same event on its own engine
//! ([`Engine::follow`]: events steer firings by their names; parameters only reach actions,
//! which the shadow does not run) and compares the two markings. On a difference it raises the
//! alarm, then takes the vehicle's marking again so that later alarms are about later steps.
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
use petrel_ipc::{MarkingMsg, Participant, Reactor, ReloadAnswer, Role, Vehicle};
use petrel_nets::compiled::{CompiledProject, PlaceRef};
use petrel_nets::semantics::Layout;
use std::collections::BTreeSet;
use std::path::Path;
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

/// The shadow's copy of the supervision: the version it follows, its engine, the vehicle's
/// marking as the deltas say, and what it saw. Sans I/O: [`shadow`] hands it what it reads.
struct Follower<'p> {
    project: &'p CompiledProject,
    engine: Engine<'p>,
    /// The vehicle's marking, from its status or its snapshots and deltas.
    mirror: Mirror,
    /// The shadow knows the vehicle's marking (from a status or a snapshot): it compares.
    synced: bool,
    /// The vehicle reloaded a version the shadow cannot read: it follows no more.
    lost: bool,
    report: ShadowReport,
}

impl<'p> Follower<'p> {
    fn new(project: &'p CompiledProject) -> Self {
        let mut engine = Engine::new(project);
        engine.start(0, &mut NullSink);
        Follower {
            project,
            engine,
            mirror: Mirror::default(),
            synced: false,
            lost: false,
            report: ShadowReport::default(),
        }
    }

    /// Takes the marking of a vehicle already flying from its heartbeat's `status` (JSON); a
    /// status that leaves the marking out (too large for a heartbeat) is not a marking.
    fn sync_on_status(&mut self, status: &str) {
        let doc: serde_json::Value = serde_json::from_str(status).unwrap_or_default();
        if doc["marking_omitted"] == true {
            return;
        }
        let Some(m) = doc["marking"].as_object() else {
            return;
        };
        for (net, places) in m {
            if net != "global" {
                self.mirror.active.insert(net.clone());
            }
            for p in places.as_array().into_iter().flatten() {
                if let Some(p) = p.as_str() {
                    self.mirror.marked.insert(format!("{net}.{p}"));
                }
            }
        }
        self.take_vehicle_marking();
        self.synced = true;
        info!("shadow synchronised on the vehicle's status");
    }

    /// The shadow's engine takes the vehicle's marking, as the mirror holds it.
    fn take_vehicle_marking(&mut self) {
        let s = self.mirror.state(self.project, self.engine.layout());
        self.engine.set_state(&s);
    }

    /// The player's accepted reloads (not dry runs): the shadow swaps its project for the new
    /// version, read from the directory the answer names, and follows again from the snapshot
    /// the player publishes after its answer; a version it cannot read raises the alarm, and
    /// the shadow follows no more (`lost`).
    fn follow_reloads(&mut self, accepted: Vec<ReloadAnswer>) {
        for a in accepted {
            if self.lost {
                return;
            }
            match crate::reload::version::load_candidate(Path::new(&a.dir), &a.source_hash, "") {
                Ok(c) => {
                    let new = crate::reload::version::leak(c.project);
                    self.project = new;
                    self.engine = Engine::new(new);
                    self.engine.start(0, &mut NullSink);
                    self.report.reloads += 1;
                    self.synced = false;
                    info!(hash = %a.source_hash, dir = %a.dir, "the vehicle reloaded its project: the shadow follows the new version");
                }
                Err(reasons) => {
                    self.lost = true;
                    self.report.alarms += 1;
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
    }

    /// A marking message of the vehicle's player: a snapshot is taken as it is; a delta is
    /// applied to the mirror and, once synchronised, its event processed on the shadow's
    /// engine and the two markings compared.
    fn marking(&mut self, msg: &MarkingMsg) {
        if msg.snapshot {
            self.mirror = Mirror::default();
            self.mirror.marked.extend(msg.marked.iter().cloned());
            self.mirror.active.extend(msg.activated.iter().cloned());
            // A snapshot marks only places; a net with a marked place is active.
            for p in &msg.marked {
                if let Some((net, _)) = p.split_once('.') {
                    if net != "global" {
                        self.mirror.active.insert(net.to_string());
                    }
                }
            }
            self.take_vehicle_marking();
            self.synced = true;
            return;
        }
        for n in &msg.activated {
            self.mirror.active.insert(n.clone());
        }
        for n in &msg.deactivated {
            self.mirror.active.remove(n);
        }
        for p in &msg.unmarked {
            self.mirror.marked.remove(p);
        }
        self.mirror.marked.extend(msg.marked.iter().cloned());
        if let (true, Some(event)) = (self.synced, msg.event.as_deref()) {
            self.compare(msg.step, event);
        }
    }

    /// Processes the vehicle's step `step` (event `event`) and compares the markings: on a
    /// difference, the alarm, and the vehicle's marking taken again, so that the next alarm is
    /// about the next difference.
    fn compare(&mut self, step: u64, event: &str) {
        self.report.steps += 1;
        let ours = match self.project.event_id(event) {
            Some(e) => {
                self.engine.follow(e, &mut NullSink);
                shadow_marking(&self.engine)
            }
            None => {
                error!(
                    event,
                    "ALARM: the vehicle processed an event this project does not declare"
                );
                self.report.alarms += 1;
                BTreeSet::new()
            }
        };
        if ours == self.mirror.marked {
            return;
        }
        self.report.alarms += 1;
        let only_vehicle: Vec<&String> = self.mirror.marked.difference(&ours).collect();
        let only_shadow: Vec<&String> = ours.difference(&self.mirror.marked).collect();
        error!(
            step,
            event,
            ?only_vehicle,
            ?only_shadow,
            "ALARM: the shadow's marking differs from the vehicle's"
        );
        let list = |v: &[&String]| v.iter().map(|s| s.as_str()).collect::<Vec<_>>().join(", ");
        eprintln!(
            "ALARM step {step} (event {event}): only in the vehicle: [{}]; only in the shadow: [{}]",
            list(&only_vehicle),
            list(&only_shadow)
        );
        self.take_vehicle_marking();
    }
}

/// The player's accepted reloads (not dry runs) answered since the last look.
fn accepted_reloads(answers: &petrel_ipc::ReloadAnswerSubscriber) -> Vec<ReloadAnswer> {
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
    accepted
}

/// Runs the shadow until SIGINT/SIGTERM (or `run_for`).
pub fn shadow(project: &CompiledProject, opts: &PlayOptions) -> Result<ShadowReport, PlayError> {
    let setup = |e: &dyn std::fmt::Display| PlayError::Setup(e.to_string());
    let vehicle = Vehicle::new(&opts.vehicle).map_err(|e| PlayError::Vehicle(e.to_string()))?;
    let role = Role::tool(&format!("shadow{}", std::process::id())).map_err(|e| setup(&e))?;
    let me = Participant::join(&vehicle, role).map_err(|e| setup(&e))?;
    let deltas = me.marking_subscriber().map_err(|e| setup(&e))?;
    let beats = me.heartbeat_subscriber().map_err(|e| setup(&e))?;
    let answers = me.reload_answer_subscriber().map_err(|e| setup(&e))?;
    let reactor = Reactor::new(opts.wait).map_err(|e| setup(&e))?;
    let mut f = Follower::new(project);
    let t0 = Instant::now();
    info!(vehicle = %opts.vehicle, "shadow started: following the vehicle's player");
    loop {
        if let Some(limit) = opts.run_for {
            if t0.elapsed() >= limit {
                break;
            }
        }
        // A vehicle already flying: take its marking from its heartbeat status.
        if !f.synced {
            let drained = beats.drain(|r| match r {
                Ok(rcv) if rcv.origin.as_str() == "player" && !f.synced => {
                    f.sync_on_status(&rcv.msg.status)
                }
                _ => {}
            });
            if let Err(e) = drained {
                warn!(error = %e, "the vehicle's heartbeats could not be read");
            }
        }
        let ready = reactor
            .wait(&[&deltas], Some(Duration::from_millis(50)))
            .map_err(|e| setup(&e))?;
        if ready.termination_requested() {
            break;
        }
        let drained = deltas.drain(|r| {
            // A reload answered before this delta was published is in its buffer by now.
            f.follow_reloads(accepted_reloads(&answers));
            if f.lost {
                return;
            }
            match r {
                Ok(rcv) if rcv.origin.as_str() == "player" => f.marking(&rcv.msg),
                Ok(_) => {}
                Err(e) => warn!(error = %e, "a marking delta could not be read"),
            }
        });
        if let Err(e) = drained {
            warn!(error = %e, "marking deltas could not be read");
        }
    }
    Ok(f.report)
}
