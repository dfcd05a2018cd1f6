//! The report: Markdown tables (docs/benchmarks.md's latency section, between markers) and
//! latency CDFs as SVG (docs/bench/).

use std::fmt::Write as _;
use std::path::Path;

use plotters::prelude::*;

use crate::alternate::{block_ratios, spread};
use crate::footprint::Footprint;
use crate::measure::{Load, ScaleResult, Settings};
use crate::roles::Res;
use crate::stats::{ratio, us, Latencies, Summary};

/// The first line of the generated section.
pub const BEGIN: &str = "<!-- latency-suite:begin (scripts/bench.sh writes this section) -->";
/// The line after it.
pub const END: &str = "<!-- latency-suite:end -->";

/// One measured series.
pub type Series = (String, Res<Latencies>);

/// A series' summary per block of part 1 (one per turn of the alternation).
pub type Blocks = (String, Vec<Summary>);

/// One figure under load: the load, the series' name, its latencies and what the load
/// processes said.
pub type LoadRow = (Load, String, Res<(Latencies, Vec<String>)>);

/// Everything one run measured.
pub struct Report {
    /// When, on what.
    pub header: String,
    /// Transport round trips: baselines first, then Petrel per strategy.
    pub transport: Vec<Series>,
    /// The transport series' blocks (measured in alternating blocks), by series name.
    pub transport_blocks: Vec<Blocks>,
    /// Under load: (load, strategy or baseline name, latencies, what the load processes said).
    pub load: Vec<LoadRow>,
    /// The vehicle path on the memory bus: baseline first.
    pub vehicle_mem: Vec<Series>,
    /// The vehicle path on vcan0 (in the VM): baseline first; Err when it could not run.
    pub vehicle_vcan: Result<Vec<Series>, String>,
    /// Footprints: baselines first.
    pub footprint: Vec<Res<Footprint>>,
    /// Resident memory of one process after opening each port (what, kB).
    pub ports: Res<Vec<(String, u64)>>,
    /// Scale, per program count.
    pub scale: Vec<Res<ScaleResult>>,
    /// The strategy of the scale runs.
    pub scale_wait: String,
}

impl Default for Report {
    fn default() -> Self {
        Report {
            header: String::new(),
            transport: Vec::new(),
            transport_blocks: Vec::new(),
            load: Vec::new(),
            vehicle_mem: Vec::new(),
            vehicle_vcan: Err("not run".to_owned()),
            footprint: Vec::new(),
            ports: Err("not run".to_owned()),
            scale: Vec::new(),
            scale_wait: String::new(),
        }
    }
}

fn summary_of(r: &Res<Latencies>) -> Option<Summary> {
    r.as_ref().ok().map(Latencies::summary)
}

fn lat_row(out: &mut String, name: &str, r: &Res<Latencies>, ratios: &[(&str, Option<Summary>)]) {
    match r {
        Ok(l) => {
            let s = l.summary();
            let _ = write!(
                out,
                "| {name} | {} | {} | {} | {} | {} | {} |",
                s.count,
                us(s.p50),
                us(s.p90),
                us(s.p99),
                us(s.p999),
                us(s.max)
            );
            for (_, b) in ratios {
                let cell = match b {
                    Some(b) => format!("{} / {}", ratio(s.p50, b.p50), ratio(s.p99, b.p99)),
                    None => "-".to_owned(),
                };
                let _ = write!(out, " {cell} |");
            }
            if l.cut_short > 0 {
                let _ = write!(
                    out,
                    " {} rounds not done within the time limit |",
                    l.cut_short
                );
            } else {
                out.push_str(" |");
            }
            out.push('\n');
        }
        Err(e) => {
            let _ = writeln!(out, "| {name} | failed: {} |", e.replace('|', "/"));
        }
    }
}

fn lat_header(out: &mut String, ratios: &[(&str, Option<Summary>)]) {
    out.push_str("| | rounds | p50 µs | p90 µs | p99 µs | p99.9 µs | max µs |");
    for (name, _) in ratios {
        let _ = write!(out, " p50 / p99 vs {name} |");
    }
    out.push_str(" note |\n|---|---:|---:|---:|---:|---:|---:|");
    for _ in ratios {
        out.push_str("---:|");
    }
    out.push_str("---|\n");
}

fn find<'a>(series: &'a [Series], name: &str) -> Option<&'a Res<Latencies>> {
    series.iter().find(|(n, _)| n == name).map(|(_, r)| r)
}

/// Transport series names.
pub const IOX_BUSY: &str = "raw iceoryx2, busy poll";
/// Transport series names.
pub const IOX_WAITSET: &str = "raw iceoryx2, WaitSet";
/// Transport series names.
pub const UDS: &str = "Unix socket";
/// Transport series names.
pub const TCP: &str = "TCP loopback";

/// The name of Petrel's series for a strategy.
pub fn petrel_name(wait: &str) -> String {
    format!("Petrel, {wait}")
}

impl Report {
    /// The Markdown section, markers included.
    pub fn markdown(&self, s: &Settings, svg_rel: &str) -> String {
        let mut o = String::new();
        let _ = writeln!(o, "{BEGIN}");
        let _ = writeln!(
            o,
            "## Latency: round trips, the vehicle path, load, footprint, scale\n\n\
             ```sh\nscripts/bench.sh                      # all of it, about 10 minutes: rewrites this section and {svg_rel}/*.svg\n\
             scripts/bench.sh --only transport     # one part (transport, vehicle, load, footprint, scale), printed only\n\
             scripts/bench.sh --short              # a few hundred rounds each (what scripts/test.sh runs)\n```\n\n{}\n",
            self.header
        );
        let _ = writeln!(
            o,
            "Every latency is an HDR histogram (hdrhistogram, 3 significant digits) of {} rounds after {} \
             rounds of warm-up that are not recorded (a measurement stops after {} s: the rounds not done \
             are said in the note). Ratios are p50 / p99 against a baseline measured in the same run: in \
             part 1 in the same minutes, in alternating blocks (below); in the other parts minutes apart \
             on the same machine.\n",
            s.rounds,
            s.warmup,
            s.max.as_secs()
        );
        if !self.transport.is_empty() {
            self.transport_md(&mut o, s);
        }
        if !self.vehicle_mem.is_empty() {
            self.vehicle_md(&mut o);
        }
        if !self.load.is_empty() {
            self.load_md(&mut o);
        }
        if !self.footprint.is_empty() {
            self.footprint_md(&mut o);
        }
        if !self.scale.is_empty() {
            self.scale_md(&mut o);
        }
        let _ = writeln!(o, "{END}");
        o
    }

    fn transport_md(&self, o: &mut String, s: &Settings) {
        let payload = crate::measure::payload_len();
        let _ = writeln!(
            o,
            "### 1. Transport: program -> player -> program\n\n\
             `scripts/bench.sh --only transport`. A program (in the bench's process) emits `pong_0(n, data)` \
             (an int and six floats: {payload} bytes of header and body in shared memory); the player \
             (`petrel play`'s loop, with its journal, `record` flush) fires `answer`, whose action calls \
             `P0.ping(n, data)`; the program times from its emit to the call's arrival. Player and program \
             use the same wait strategy (`spin-then-block:200` spins 200 µs, then sleeps). Baselines, same \
             run, same {payload} bytes each way between two processes: raw iceoryx2 publish-subscribe \
             ping-pong (busy polling both sides; and sleeping in a WaitSet woken by an event service), \
             and a Unix-domain stream socket and TCP loopback (`TCP_NODELAY`, what ProCoSA used) with \
             blocking reads.\n"
        );
        let blocks = s.blocks.max(1);
        let _ = writeln!(
            o,
            "**Measured in alternating blocks**, so that a ratio compares the same minutes of the \
             machine (whose CPUs go from idle and slow to wake to busy with others' work within \
             seconds). The seven set-ups are started and warmed up one at a time ({} rounds each, \
             the others paused), then take turns: each measures a block of about {} rounds (after {} \
             rounds not recorded) while the others are paused, {blocks} blocks each, the turns going \
             forwards then backwards through raw iceoryx2 busy poll, Petrel spin, spin-then-block, \
             raw iceoryx2 WaitSet, TCP, Petrel block, Unix socket (each goal's pair next to each \
             other). Each row is all its blocks in one histogram (the time limit counts all of a \
             set-up's blocks together). Paused means that nothing of it \
             runs: the player is stopped (SIGSTOP; it runs `petrel play`'s loop, which has no pause \
             of its own) and continued before its block, raw iceoryx2's answering process sleeps \
             until it is told to go on, a socket's sleeps in its read anyway. The goals give the \
             pair's p50 ratio block by block too: the median, the range, and the blocks within the \
             goal.\n",
            s.warmup,
            s.rounds / blocks,
            (s.warmup / blocks).max(1)
        );
        let base = [
            (
                "iceoryx2 busy",
                find(&self.transport, IOX_BUSY).and_then(summary_of),
            ),
            (
                "Unix socket",
                find(&self.transport, UDS).and_then(summary_of),
            ),
        ];
        lat_header(o, &base);
        for (name, r) in &self.transport {
            lat_row(o, name, r, &base);
        }
        let p = |w: &str| find(&self.transport, &petrel_name(w)).and_then(summary_of);
        let goal = |name: &str,
                    a: Option<Summary>,
                    b: Option<Summary>,
                    k: f64,
                    what: &str,
                    per_block: String| match (a, b) {
            (Some(a), Some(b)) => format!(
                "- {name}: p50 {} µs against {what} {} µs x {k}: **{}** ({}){per_block}.",
                us(a.p50),
                us(b.p50),
                if a.p50 <= b.p50 * k { "met" } else { "not met" },
                ratio(a.p50, b.p50)
            ),
            _ => format!("- {name}: not measured."),
        };
        let _ = writeln!(
            o,
            "\nGoals:\n{}\n{}\n\n![round trip CDFs](bench/transport.svg)\n",
            goal(
                "spin within 3x raw iceoryx2 busy poll",
                p("spin"),
                base[0].1,
                3.0,
                "raw iceoryx2 busy poll",
                self.block_spread(&petrel_name("spin"), IOX_BUSY, 3.0)
            ),
            goal(
                "block no slower than the Unix socket round trip",
                p("block"),
                base[1].1,
                1.0,
                "the Unix socket",
                self.block_spread(&petrel_name("block"), UDS, 1.0)
            )
        );
    }

    /// `a`'s p50 against `b`'s block by block (blocks of the same turn), as the end of a goal's
    /// line: the median, the range, how many blocks are within `goal` (two decimals: near a
    /// goal of 1x, "1.0x" would not say on which side a block is).
    fn block_spread(&self, a: &str, b: &str, goal: f64) -> String {
        let blocks = |name: &str| {
            self.transport_blocks
                .iter()
                .find(|(n, _)| n == name)
                .map(|(_, v)| v.as_slice())
                .unwrap_or_default()
        };
        match spread(&block_ratios(blocks(a), blocks(b)), goal) {
            Some(s) => format!(
                "; block by block ({} pairs of blocks of the same turn): median {:.2}x, {:.2}x to \
                 {:.2}x, within {goal}x in {} of {}",
                s.n, s.median, s.min, s.max, s.within, s.n
            ),
            None => String::new(),
        }
    }

    fn vehicle_md(&self, o: &mut String) {
        let _ = writeln!(
            o,
            "### 2. The vehicle path: sensor frame -> rule -> event -> transition -> call -> command frame\n\n\
             `scripts/bench.sh --only vehicle`. A probe on the bus writes `Ping(flip, seq)`; the data server's \
             edge rule makes `ping(seq)` of every frame; the player's transition calls `CAN.Pong(seq)`; the \
             data server sends the `Pong` frame; the probe times from its write to the `Pong` it reads \
             (sleeping on its descriptor, as a node would). Player and data server use the strategy of \
             the row. Baseline: the same frames echoed by a bare reader/writer on the same bus.\n\n\
             **In-memory bus** (`petrel bridge --bus memory`'s bus; it lives inside the data server's \
             process, so the probe and the echo are threads of that process; the player is a process of \
             its own):\n"
        );
        let base = [(
            "bare echo",
            find(&self.vehicle_mem, "bare echo").and_then(summary_of),
        )];
        lat_header(o, &base);
        for (name, r) in &self.vehicle_mem {
            lat_row(o, name, r, &base);
        }
        o.push_str("\n**vcan0 in the VM** (`scripts/vcan-vm.sh`: Debian's kernel under qemu TCG, pure emulation, 2 virtual CPUs; probe, echo, data server and player are processes of their own; the bare echo uses the same SocketCAN socket wrapper without the data server): ");
        match &self.vehicle_vcan {
            Ok(series) => {
                o.push_str("emulated CPUs are many times slower than the host, so only the ratios mean anything.\n\n");
                let base = [(
                    "bare SocketCAN echo",
                    find(series, "bare SocketCAN echo").and_then(summary_of),
                )];
                lat_header(o, &base);
                for (name, r) in series {
                    lat_row(o, name, r, &base);
                }
            }
            Err(e) => {
                let _ = writeln!(o, "not measured in this run: {e}");
            }
        }
        o.push_str("\n![vehicle path CDFs](bench/vehicle.svg)\n\n");
    }

    fn load_md(&self, o: &mut String) {
        let _ = writeln!(
            o,
            "### 3. Under load\n\n\
             `scripts/bench.sh --only load`. The round trip of part 1 (Petrel per strategy; the Unix socket \
             as the baseline) while (a) a program streams `tick(n)` at 10 kHz into the player (each fires \
             a transition and is journaled) and a monitor follows the heartbeats (status JSON) and the \
             marking deltas, and (b) one busy process per CPU ({} here) shares the machine. Ratios \
             against the same figure without load in this run.\n",
            crate::measure::cpus()
        );
        for load in [Load::Events, Load::Cpu] {
            let title = match load {
                Load::Events => "10 kHz event stream + status reader",
                _ => "CPU shared with busy processes",
            };
            let _ = writeln!(o, "**{title}:**\n");
            let rows: Vec<&LoadRow> = self.load.iter().filter(|(l, _, _)| *l == load).collect();
            o.push_str("| | rounds | p50 µs | p90 µs | p99 µs | p99.9 µs | max µs | p50 / p99 vs idle | note |\n|---|---:|---:|---:|---:|---:|---:|---:|---|\n");
            for (_, name, r) in rows {
                let idle = find(&self.transport, name).and_then(summary_of);
                match r {
                    Ok((l, said)) => {
                        let s = l.summary();
                        let vs = idle
                            .map(|b| format!("{} / {}", ratio(s.p50, b.p50), ratio(s.p99, b.p99)))
                            .unwrap_or_else(|| "-".to_owned());
                        let mut note = load_note(said);
                        if l.cut_short > 0 {
                            note = format!("{} rounds not done in time. {note}", l.cut_short);
                        }
                        let _ = writeln!(
                            o,
                            "| {name} | {} | {} | {} | {} | {} | {} | {vs} | {} |",
                            s.count,
                            us(s.p50),
                            us(s.p90),
                            us(s.p99),
                            us(s.p999),
                            us(s.max),
                            note.replace('|', "/")
                        );
                    }
                    Err(e) => {
                        let _ = writeln!(o, "| {name} | failed: {} |", e.replace('|', "/"));
                    }
                }
            }
            o.push('\n');
        }
        o.push_str("![under load CDFs](bench/load.svg)\n\n");
    }

    fn footprint_md(&self, o: &mut String) {
        o.push_str("### 4. Footprint\n\n`scripts/bench.sh --only footprint`. Each process started alone on a fresh vehicle (the last program after a player, whose project sizes the events service); ready is its first heartbeat on the vehicle (the player: project loaded, checked, journal opened, services up; the data server likewise) or its ready line (a program); memory read from `/proc/PID/status` one second after ready. The goal: under 20 MB resident for the player on Redermor.\n\n| process | command | ready ms | VmRSS MB | VmHWM MB | x baseline RSS | iceoryx2 shared memory resident MB | heap MB | binary MB |\n|---|---|---:|---:|---:|---:|---:|---:|---:|\n");
        let base = self
            .footprint
            .first()
            .and_then(|f| f.as_ref().ok())
            .map(|f| f.rss_kb);
        for f in &self.footprint {
            match f {
                Ok(f) => {
                    let kind = |k: &str| {
                        f.breakdown
                            .as_ref()
                            .and_then(|b| b.kinds.get(k).copied())
                            .map(|v| format!("{:.1}", v as f64 / 1024.0))
                            .unwrap_or_else(|| "-".to_owned())
                    };
                    let _ = writeln!(
                        o,
                        "| {} | `{}` | {} | {:.1} | {:.1} | {} | {} | {} | {} |",
                        f.what,
                        f.command,
                        f.ready
                            .map(|d| format!("{:.0}", d.as_secs_f64() * 1000.0))
                            .unwrap_or_else(|| "-".to_owned()),
                        f.rss_kb as f64 / 1024.0,
                        f.hwm_kb as f64 / 1024.0,
                        base.map(|b| ratio(f.rss_kb as f64, b as f64))
                            .unwrap_or_else(|| "-".to_owned()),
                        kind("shared memory (iceoryx2)"),
                        kind("heap and anonymous"),
                        kind("binary"),
                    );
                }
                Err(e) => {
                    let _ = writeln!(o, "| not measured: {} |", e.replace('|', "/"));
                }
            }
        }
        if let Ok(steps) = &self.ports {
            o.push_str("\nWhere a Petrel process's memory goes: one process (`petrel-bench role ports`) joins a fresh vehicle and opens a player's ports, then a program's, reading its own VmRSS after each:\n\n| after | VmRSS MB | added MB |\n|---|---:|---:|\n");
            let mut prev = None;
            for (what, kb) in steps {
                let added = prev
                    .map(|p: u64| format!("{:+.1}", (*kb as f64 - p as f64) / 1024.0))
                    .unwrap_or_default();
                let _ = writeln!(o, "| {what} | {:.1} | {added} |", *kb as f64 / 1024.0);
                prev = Some(*kb);
            }
        }
        o.push('\n');
    }

    fn scale_md(&self, o: &mut String) {
        let _ = writeln!(
            o,
            "### 5. Scale\n\n`scripts/bench.sh --only scale`. N programs, each a process of its own with its own \
             event and net, all doing round trips with one player at once for the same time ({} wait \
             strategy everywhere: spinning 50 processes on {} CPUs would measure the scheduler). \
             Events/s counts every round trip of every program (one event in and one call out each). \
             Ratios against one program, same run.\n\n\
             | programs | round trips | p50 µs | p90 µs | p99 µs | p99.9 µs | max µs | events/s | p50 vs 1 program | player VmRSS MB |\n\
             |---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|",
            self.scale_wait,
            crate::measure::cpus()
        );
        let one = self
            .scale
            .iter()
            .filter_map(|r| r.as_ref().ok())
            .find(|r| r.programs == 1)
            .map(|r| r.latencies.summary());
        for r in &self.scale {
            match r {
                Ok(r) => {
                    let s = r.latencies.summary();
                    let _ = writeln!(
                        o,
                        "| {} | {} | {} | {} | {} | {} | {} | {:.0} | {} | {:.1} |",
                        r.programs,
                        s.count,
                        us(s.p50),
                        us(s.p90),
                        us(s.p99),
                        us(s.p999),
                        us(s.max),
                        r.events_per_s,
                        one.map(|b| ratio(s.p50, b.p50))
                            .unwrap_or_else(|| "-".to_owned()),
                        r.player_rss_kb as f64 / 1024.0
                    );
                }
                Err(e) => {
                    let _ = writeln!(o, "| failed: {} |", e.replace('|', "/"));
                }
            }
        }
        o.push_str("\n![scale CDFs](bench/scale.svg)\n\n");
    }

    /// Writes the CDF plots into `dir`.
    pub fn plots(&self, dir: &Path) -> Res<Vec<String>> {
        std::fs::create_dir_all(dir).map_err(|e| format!("{}: {e}", dir.display()))?;
        let mut written = Vec::new();
        let ok = |v: &[Series]| -> Vec<(String, Latencies)> {
            v.iter()
                .filter_map(|(n, r)| r.as_ref().ok().map(|l| (n.clone(), l.clone())))
                .collect()
        };
        let mut plot = |file: &str, title: &str, series: Vec<(String, Latencies)>| -> Res<()> {
            if series.is_empty() {
                return Ok(());
            }
            let path = dir.join(file);
            cdf_svg(&path, title, &series)?;
            written.push(path.display().to_string());
            Ok(())
        };
        plot(
            "transport.svg",
            "Round trip, program -> player -> program, and baselines",
            ok(&self.transport),
        )?;
        let mut v = ok(&self.vehicle_mem)
            .into_iter()
            .map(|(n, l)| (format!("memory bus: {n}"), l))
            .collect::<Vec<_>>();
        if let Ok(vc) = &self.vehicle_vcan {
            v.extend(
                ok(vc)
                    .into_iter()
                    .map(|(n, l)| (format!("vcan0 (VM): {n}"), l)),
            );
        }
        plot(
            "vehicle.svg",
            "Vehicle path: Ping frame -> ... -> Pong frame",
            v,
        )?;
        let load: Vec<(String, Latencies)> = self
            .load
            .iter()
            .filter_map(|(l, n, r)| {
                let what = match l {
                    Load::Events => "10 kHz events",
                    Load::Cpu => "busy CPUs",
                    Load::Idle => "idle",
                };
                r.as_ref()
                    .ok()
                    .map(|(lat, _)| (format!("{n} ({what})"), lat.clone()))
            })
            .collect();
        plot("load.svg", "Round trip under load", load)?;
        let scale: Vec<(String, Latencies)> = self
            .scale
            .iter()
            .filter_map(|r| r.as_ref().ok())
            .map(|r| (format!("{} program(s)", r.programs), r.latencies.clone()))
            .collect();
        plot("scale.svg", "Round trip with N programs attached", scale)?;
        Ok(written)
    }
}

/// What the background processes said, for people: the stream's rate, the monitor's reads.
fn load_note(said: &[String]) -> String {
    let mut out = Vec::new();
    for t in said {
        let w: Vec<&str> = t.split_whitespace().collect();
        match w.as_slice() {
            ["SENT", n, "SECS", secs, "ERRORS", e, ..] => {
                let rate =
                    n.parse::<f64>().unwrap_or(0.0) / secs.parse::<f64>().unwrap_or(1.0).max(1e-9);
                out.push(format!(
                    "stream: {n} events in {secs} s ({rate:.0}/s), {e} not sent"
                ));
            }
            ["READ", b, "HEARTBEATS", d, "DELTAS"] => {
                out.push(format!("monitor: {b} heartbeats, {d} marking deltas read"));
            }
            _ if !t.is_empty() => out.push(t.clone()),
            _ => {}
        }
    }
    out.join("; ")
}

/// A latency CDF plot, log-scaled time axis.
pub fn cdf_svg(path: &Path, title: &str, series: &[(String, Latencies)]) -> Res<()> {
    let mut lo = f64::MAX;
    let mut hi: f64 = 0.0;
    let curves: Vec<(String, Vec<(f64, f64)>)> =
        series.iter().map(|(n, l)| (n.clone(), l.cdf())).collect();
    for (_, c) in &curves {
        for (x, _) in c {
            lo = lo.min(*x);
            hi = hi.max(*x);
        }
    }
    if curves.iter().all(|(_, c)| c.is_empty()) {
        return Ok(());
    }
    let lo = (lo * 0.8).max(0.01);
    let hi = (hi * 1.25).max(lo * 10.0);
    let root = SVGBackend::new(path, (1000, 620)).into_drawing_area();
    let e = |e: &dyn std::fmt::Debug| format!("{}: {e:?}", path.display());
    root.fill(&WHITE).map_err(|x| e(&x))?;
    let mut chart = ChartBuilder::on(&root)
        .caption(title, ("sans-serif", 22))
        .margin(12)
        .x_label_area_size(45)
        .y_label_area_size(55)
        .build_cartesian_2d((lo..hi).log_scale(), 0.0..1.0)
        .map_err(|x| e(&x))?;
    chart
        .configure_mesh()
        .x_desc("round trip, µs (log scale)")
        .y_desc("fraction of rounds at or below")
        .draw()
        .map_err(|x| e(&x))?;
    for (i, (name, c)) in curves.iter().enumerate() {
        let color = Palette99::pick(i).to_rgba();
        // A step curve: each bucket's fraction holds until the next value.
        let mut pts = Vec::with_capacity(c.len() * 2);
        let mut prev = 0.0;
        for (x, y) in c {
            pts.push((*x, prev));
            pts.push((*x, *y));
            prev = *y;
        }
        chart
            .draw_series(LineSeries::new(pts, color.stroke_width(2)))
            .map_err(|x| e(&x))?
            .label(name.clone())
            .legend(move |(x, y)| {
                PathElement::new(vec![(x, y), (x + 18, y)], color.stroke_width(2))
            });
    }
    chart
        .configure_series_labels()
        .position(SeriesLabelPosition::LowerRight)
        .background_style(WHITE.mix(0.85))
        .border_style(BLACK)
        .draw()
        .map_err(|x| e(&x))?;
    root.present().map_err(|x| e(&x))?;
    Ok(())
}

/// Replaces the section between the markers in `doc` (or appends it).
pub fn splice(doc: &str, section: &str) -> String {
    match (doc.find(BEGIN), doc.find(END)) {
        (Some(a), Some(b)) if b > a => {
            let end = b + END.len();
            let rest = doc[end..].strip_prefix('\n').unwrap_or(&doc[end..]);
            format!("{}{}{}", &doc[..a], section, rest)
        }
        _ => format!(
            "{}\n{}",
            doc.trim_end_matches('\n').to_owned() + "\n",
            section
        ),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn splice_replaces_only_the_section() {
        let doc = format!("# B\n\nbefore\n{BEGIN}\nold\n{END}\nafter\n");
        let new = splice(&doc, &format!("{BEGIN}\nnew\n{END}\n"));
        assert_eq!(new, format!("# B\n\nbefore\n{BEGIN}\nnew\n{END}\nafter\n"));
        let appended = splice("# B\n", &format!("{BEGIN}\nx\n{END}\n"));
        assert!(appended.starts_with("# B\n\n"));
        assert!(appended.ends_with(&format!("{END}\n")));
    }
}
