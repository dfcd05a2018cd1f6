//! The carried messages' protocol between two gateway cores, sans I/O (`petrel_gateway::reliable`
//! and its use by `Core`): the test is the link, dropping, duplicating, reordering and delaying
//! copies, stopping a gateway's clock and restarting either side.

use petrel_gateway::core::{Counts, Route};
use petrel_gateway::link::{LinkKind, LinkMsg};
use petrel_gateway::reliable::{Failure, MAX_BUFFERED};
use petrel_gateway::{Core, PeerChange, Plan};

const S: u64 = 1_000_000;

/// The player and ECHO's caller on A, ECHO and the operator's senders on B.
fn plan(me: &str) -> Plan {
    Plan {
        computer: me.into(),
        peers: ["A", "B"]
            .iter()
            .filter(|c| **c != me)
            .map(|c| c.to_string())
            .collect(),
        player_computer: "A".into(),
        hosts: [("ECHO".to_string(), "B".to_string())].into(),
        signals_computer: None,
        detection_us: S,
        retention_us: 10 * S,
    }
}

struct Side {
    core: Core,
    /// Its clock, as far as it ticked.
    now: u64,
    /// What it delivered to its processes, in order: (kind, body).
    delivered: Vec<(String, Vec<u8>)>,
    changes: Vec<PeerChange>,
}

impl Side {
    fn new(me: &str, incarnation: u64) -> Side {
        let mut core = Core::new(plan(me), incarnation);
        core.set_hold_on_restore(me == "A");
        Side {
            core,
            now: 0,
            delivered: Vec::new(),
            changes: Vec::new(),
        }
    }

    /// Runs its loop until `t`, ticking as the process does (every beacon period).
    fn at(&mut self, t: u64) {
        while self.now < t {
            self.now = (self.now + S / 4).min(t);
            let changes = self.core.tick(self.now);
            self.changes.extend(changes);
        }
    }

    fn beacon(&mut self, now: u64) -> LinkMsg {
        self.core.outgoing(
            "gateway",
            (0, 0),
            LinkKind::Beacon {
                alive: Vec::new(),
                follows: self.core.follows(),
            },
            Vec::new(),
            now,
        )
    }

    /// Everything it puts on the link at `now`: its copies due and its acknowledgements.
    fn puts(&mut self, now: u64) -> Vec<LinkMsg> {
        let mut out: Vec<LinkMsg> = self.core.due(now).into_iter().map(|(m, _)| m).collect();
        out.extend(self.core.acks_due(now));
        out
    }

    /// Takes what the link brings at `now`, delivering as the runtime does (`refuse`: the
    /// local delivery fails with that reason).
    fn hear(&mut self, msgs: &[LinkMsg], now: u64, refuse: Option<&str>) -> Vec<Route> {
        let mut routes = Vec::new();
        for m in msgs {
            let route = self.core.on_link(m, now, &mut self.changes);
            if route == Route::Deliver {
                self.deliver(m, refuse);
            }
            routes.push(route);
        }
        routes
    }

    fn deliver(&mut self, m: &LinkMsg, refuse: Option<&str>) {
        if refuse.is_none() {
            self.delivered
                .push((m.kind.name().to_owned(), m.body.clone()));
        }
        self.core.taken(m, refuse.map(str::to_owned));
    }

    fn release(&mut self) {
        for m in self.core.take_released() {
            self.deliver(&m, None);
        }
    }

    fn counts(&self, kind: &str) -> Counts {
        self.core
            .counters
            .kinds
            .get(kind)
            .copied()
            .unwrap_or_default()
    }

    fn event(&mut self, n: u8, now: u64) -> bool {
        self.core.carry(
            "tool/send1",
            (7, u64::from(n)),
            LinkKind::Event,
            vec![n],
            now,
        )
    }

    fn call(&mut self, n: u8, now: u64) -> bool {
        let kind = LinkKind::Call {
            program: "ECHO".into(),
        };
        self.core
            .carry("player", (3, u64::from(n)), kind, vec![n], now)
    }
}

/// A and B hear each other's beacons at `now`.
fn meet(a: &mut Side, b: &mut Side, now: u64) {
    let (ba, bb) = (a.beacon(now), b.beacon(now));
    b.hear(&[ba], now, None);
    a.hear(&[bb], now, None);
}

/// Both run until `to`, hearing each other's beacons (and nothing else).
fn run(a: &mut Side, b: &mut Side, to: u64) {
    while a.now < to {
        let t = (a.now + S / 4).min(to);
        a.at(t);
        b.at(t);
        meet(a, b, t);
    }
}

fn bodies(s: &Side) -> Vec<u8> {
    s.delivered.iter().map(|(_, b)| b[0]).collect()
}

fn reasons(f: &[Failure]) -> Vec<String> {
    f.iter().map(|f| f.reason.clone()).collect()
}

#[test]
fn events_sent_during_an_outage_arrive_in_order_after_the_restored_event() {
    let (mut a, mut b) = (Side::new("A", 1), Side::new("B", 2));
    meet(&mut a, &mut b, 0);
    // The cable is cut: B's copies go nowhere.
    for n in 1..=3 {
        assert!(b.event(n, S / 10));
    }
    assert_eq!(b.puts(S / 10).len(), 3, "each sent once at once");
    assert!(
        b.puts(S / 5).is_empty(),
        "not again before the resend delay"
    );
    a.at(2 * S);
    b.at(2 * S);
    assert!(
        b.puts(2 * S).is_empty(),
        "nothing is sent to a lost computer"
    );
    assert_eq!(b.core.peers()["A"].buffered, 3);
    a.at(6 * S);
    b.at(6 * S);
    // Back at 6 s (within retention - detection): B hears A, and sends everything again.
    let beacon = a.beacon(6 * S);
    b.hear(&[beacon], 6 * S, None);
    let due = b.core.due(6 * S);
    assert!(due.iter().all(|(_, again)| *again), "each a retransmission");
    let copies: Vec<LinkMsg> = due.into_iter().map(|(m, _)| m).collect();
    assert_eq!(copies.len(), 3);
    a.changes.clear();
    let beacon = b.beacon(6 * S);
    let mut routes = a.hear(&[beacon], 6 * S, None);
    routes.extend(a.hear(&copies, 6 * S, None));
    assert_eq!(a.changes, vec![PeerChange::Restored("B".into())]);
    assert_eq!(&routes[1..], &[Route::Held, Route::Held, Route::Held]);
    // The restored event went to the player as the gateway's message 5: the events wait until
    // the player's heartbeat says it took it.
    a.core.link_event_sent("B", Some(5));
    a.core.player_took(4);
    a.release();
    assert!(a.delivered.is_empty());
    a.core.player_took(5);
    a.release();
    assert_eq!(bodies(&a), [1, 2, 3]);
    // A acknowledges; B's buffer empties; nothing was given up.
    let acks = a.puts(6 * S);
    b.hear(&acks, 6 * S, None);
    assert_eq!(b.core.buffered("A"), 0);
    b.at(6 * S + 1);
    assert_eq!(b.core.peers()["A"].buffered, 0);
    let e = b.counts("event");
    assert_eq!((e.to_link, e.carried, e.given_up), (0, 3, 0));
    assert!(b.core.take_failures().is_empty());
    let e = a.counts("event");
    assert_eq!((e.from_link, e.discarded), (3, 0));
}

#[test]
fn duplicates_and_reordered_copies_are_not_taken_twice() {
    let (mut a, mut b) = (Side::new("A", 1), Side::new("B", 2));
    meet(&mut a, &mut b, 0);
    for n in 1..=3 {
        b.event(n, 0);
    }
    let copies = b.puts(0);
    // 3 before 2: not taken (2 is missing); 1, then 1 again: once.
    let routes = a.hear(
        &[copies[0].clone(), copies[2].clone(), copies[0].clone()],
        S / 100,
        None,
    );
    assert_eq!(routes, [Route::Deliver, Route::Discarded, Route::Discarded]);
    // The acknowledgement (1 taken) is lost; B sends 2 and 3 again after the resend delay, and
    // 1 too: A takes 2 and 3 and discards 1.
    let _lost = a.puts(S / 100);
    b.at(S);
    let again = b.puts(S);
    assert_eq!(again.len(), 3);
    let routes = a.hear(&again, S + 1, None);
    assert_eq!(routes, [Route::Discarded, Route::Deliver, Route::Deliver]);
    assert_eq!(bodies(&a), [1, 2, 3]);
    let acks = a.puts(S + 1);
    b.hear(&acks, S + 2, None);
    assert_eq!(b.counts("event").carried, 3);
    assert_eq!(b.core.buffered("A"), 0);
    // 3 out of order, then 1 twice.
    assert_eq!(a.counts("event").discarded, 3);
}

#[test]
fn past_retention_every_sender_is_told_and_no_late_copy_is_taken() {
    let (mut a, mut b) = (Side::new("A", 1), Side::new("B", 2));
    meet(&mut a, &mut b, 0);
    // The player's call to ECHO on B, and an operator's event on B, just as the link goes.
    assert!(a.call(1, S / 10));
    assert!(b.event(9, S / 10));
    let in_flight = a.puts(S / 10);
    b.puts(S / 10);
    for t in [2, 5, 8] {
        a.at(t * S);
        b.at(t * S);
    }
    // B comes back at 9.5 s: the call is older than retention - detection: not sent again.
    let beacon = b.beacon(9 * S + S / 2);
    a.at(9 * S + S / 2);
    a.hear(&[beacon], 9 * S + S / 2, None);
    assert!(a.puts(9 * S + S / 2).is_empty());
    assert!(a.core.take_failures().is_empty(), "not given up yet");
    a.at(10 * S + S / 10);
    b.at(10 * S + S / 10);
    let (fa, fb) = (a.core.take_failures(), b.core.take_failures());
    assert_eq!(fa.len(), 1);
    assert!(matches!(fa[0].msg.kind, LinkKind::Call { .. }));
    assert_eq!((fa[0].msg.origin.as_str(), fa[0].msg.seq), ("player", 1));
    assert!(reasons(&fa)[0].contains("within 10 s"), "{fa:?}");
    assert_eq!(fb.len(), 1);
    assert_eq!((fb[0].msg.sender, fb[0].msg.seq), (7, 9));
    assert_eq!(a.counts("call").given_up, 1);
    // The copy of the call that waited 12 s in a buffer (B was stopped) reaches B now: too
    // late, not taken (its caller was told it failed).
    let routes = b.hear(&in_flight, 12 * S, None);
    assert_eq!(routes, [Route::Discarded]);
    assert!(b.delivered.is_empty());
}

#[test]
fn a_refusal_at_the_destination_is_carried_back() {
    let (mut a, mut b) = (Side::new("A", 1), Side::new("B", 2));
    meet(&mut a, &mut b, 0);
    a.call(1, 0);
    let copies = a.puts(0);
    b.hear(&copies, 1, Some("no receiver: ECHO is not running"));
    let acks = b.puts(1);
    a.hear(&acks, 2, None);
    let f = a.core.take_failures();
    assert_eq!(f.len(), 1);
    assert!(
        f[0].reason
            .contains("refused on computer `B`: no receiver: ECHO is not running"),
        "{f:?}"
    );
    assert_eq!(a.core.buffered("B"), 0);
}

#[test]
fn a_full_buffer_refuses_at_once_and_the_stream_goes_on() {
    let (mut a, mut b) = (Side::new("A", 1), Side::new("B", 2));
    meet(&mut a, &mut b, 0);
    a.at(2 * S);
    b.at(2 * S);
    for n in 0..MAX_BUFFERED {
        assert!(b.event((n % 250) as u8, 3 * S));
    }
    assert!(!b.event(251, 3 * S), "the buffer is full");
    let f = b.core.take_failures();
    assert!(reasons(&f)[0].contains("the buffer is full"), "{f:?}");
    // Back: everything buffered arrives, numbered without a gap.
    meet(&mut a, &mut b, 4 * S);
    let copies = b.puts(4 * S);
    assert_eq!(copies.len(), MAX_BUFFERED);
    let routes = a.hear(&copies, 4 * S, None);
    assert!(routes.iter().all(|r| *r == Route::Held));
    a.core.link_event_sent("B", None);
    a.release();
    assert_eq!(a.delivered.len(), MAX_BUFFERED);
}

#[test]
fn a_gateway_that_stood_still_judges_the_link_only_once_it_listens_again() {
    let (mut a, mut b) = (Side::new("A", 1), Side::new("B", 2));
    meet(&mut a, &mut b, 0);
    a.call(1, S / 10);
    let copies = a.puts(S / 10);
    // B takes the call at once and acknowledges; A is stopped (SIGSTOP) for 12 s.
    b.hear(&copies, S / 10, None);
    let acks = b.puts(S / 10);
    // A runs again at 12 s: its first tick finds B silent, but gives nothing up: it stood
    // still, its messages aged only while it ran.
    a.now = 12 * S;
    a.core.tick(12 * S);
    assert!(a.core.take_failures().is_empty());
    // Then it reads what waited for it: the acknowledgement.
    a.hear(&acks, 12 * S + 1, None);
    assert_eq!(a.core.buffered("B"), 0);
    assert_eq!(a.counts("call").carried, 1);
    // Without acknowledgement, a message is given up after retention of the gateway running.
    a.call(2, 12 * S);
    let mut t = 12 * S;
    while a.core.take_failures().is_empty() {
        t += S / 4;
        a.at(t);
        assert!(t < 30 * S);
    }
    assert!(t >= 22 * S, "given up at {t}");
}

#[test]
fn a_restarted_gateway_starts_new_streams_and_old_numbers_do_not_confuse_it() {
    let (mut a, mut b) = (Side::new("A", 1), Side::new("B", 2));
    meet(&mut a, &mut b, 0);
    b.event(1, 0);
    b.event(2, 0);
    let first = b.puts(0);
    a.hear(&first, 1, None);
    assert_eq!(bodies(&a), [1, 2]);
    // B restarts. Until its predecessor is silent past the detection bound, A takes the new
    // incarnation for a second gateway of B and refuses it; past the bound, for its restart:
    // it numbers from 1 again, and A takes it as new.
    let mut b2 = Side::new("B", 22);
    let early = b2.beacon(S / 2);
    assert!(matches!(
        a.hear(&[early], S / 2, None)[..],
        [Route::Claim(_)]
    ));
    meet(&mut a, &mut b2, 2 * S);
    assert_eq!(a.core.peers()["B"].restarts, 1);
    b2.event(3, 2 * S);
    let copies = b2.puts(2 * S);
    assert_eq!(copies[0].carried.as_ref().map(|c| c.seq), Some(1));
    assert_eq!(a.hear(&copies, 2 * S, None), [Route::Deliver]);
    let acks = a.puts(2 * S);
    b2.hear(&acks, 2 * S, None);
    assert_eq!(b2.core.buffered("A"), 0);
    // A late copy of the old incarnation's second message is not taken again: A follows the
    // new incarnation now, and refuses the other's messages as it would a second gateway's.
    assert!(matches!(
        a.hear(&first[1..], 2 * S + 1, None)[..],
        [Route::Claim(_)]
    ));
    assert_eq!(bodies(&a), [1, 2, 3]);

    // A restarts with a call of B's... (here: an event of B's) numbered but unacknowledged:
    // given up (A may have delivered it before it stopped), and what waits is numbered anew.
    b2.event(4, 2 * S);
    let to_old_a = b2.puts(2 * S);
    b2.event(5, 2 * S);
    let mut a2 = Side::new("A", 11);
    meet(&mut a2, &mut b2, 4 * S);
    let f = b2.core.take_failures();
    assert_eq!(f.len(), 1);
    assert!(reasons(&f)[0].contains("restarted"), "{f:?}");
    assert_eq!(f[0].msg.body, [4]);
    let copies = b2.puts(4 * S);
    assert_eq!(copies.len(), 1);
    assert_eq!(
        copies[0]
            .carried
            .as_ref()
            .map(|c| (c.seq, c.to_incarnation)),
        Some((1, 11))
    );
    // The copy for its predecessor is not taken by the new A.
    assert_eq!(a2.hear(&to_old_a, 4 * S, None), [Route::Discarded]);
    assert_eq!(a2.hear(&copies, 4 * S, None), [Route::Deliver]);
    assert_eq!(bodies(&a2), [5]);
}

#[test]
fn a_second_gateway_is_neither_taken_nor_acknowledged_and_the_first_stream_goes_on() {
    let (mut a, mut b) = (Side::new("A", 1), Side::new("B", 2));
    meet(&mut a, &mut b, 0);
    // The player's call to ECHO, on its way to B's first gateway.
    a.call(1, 0);
    let call = a.puts(0);
    // A second gateway of B, with the vehicle's keys, while the first is up: it hears A and
    // sends it an event; A refuses all of it and acknowledges nothing of it.
    let mut second = Side::new("B", 3);
    let beacon = a.beacon(S / 10);
    second.hear(&[beacon], S / 10, None);
    assert!(second.event(9, S / 10));
    let mut from_second = vec![second.beacon(S / 10)];
    from_second.extend(second.puts(S / 10));
    let routes = a.hear(&from_second, S / 10, None);
    assert!(
        routes.iter().all(|r| matches!(r, Route::Claim(_))),
        "{routes:?}"
    );
    assert!(a.delivered.is_empty());
    assert!(a.puts(S / 10).is_empty(), "nothing acknowledged to it");
    assert_eq!(a.core.counters.claims_refused["B"], 2);
    // The second gateway takes nothing meant for the first.
    assert_eq!(second.hear(&call, S / 10, None), [Route::Discarded]);
    // The first goes on: no restart, the call not given up, its stream and A's unchanged.
    b.hear(&call, S / 10, None);
    b.event(1, S / 10);
    let puts = b.puts(S / 10);
    a.hear(&puts, S / 10, None);
    assert_eq!(bodies(&a), [1]);
    let acks = a.puts(S / 10);
    b.hear(&acks, S / 10, None);
    assert_eq!((b.core.buffered("A"), a.core.buffered("B")), (0, 0));
    assert!(a.core.take_failures().is_empty());
    assert_eq!(a.core.peers()["B"].restarts, 0);
    assert_eq!(a.counts("call").carried, 1);
    let e = a.counts("event");
    assert_eq!(
        e.from_link,
        e.delivered + e.refused + e.not_mine + e.unheard + e.discarded + 1,
        "the runtime counts deliveries: {e:?}"
    );
}

#[test]
fn a_message_its_computer_may_not_send_is_refused_back_and_the_stream_goes_on() {
    let (mut a, mut b) = (Side::new("A", 1), Side::new("B", 2));
    meet(&mut a, &mut b, 0);
    a.at(2 * S);
    b.at(2 * S);
    // While the link is out, B takes an event claiming to be the player's (its origin is
    // A's), then a tool's. Back, both wait for the restored event; the first is refused as
    // they are released, the second delivered.
    assert!(b
        .core
        .carry("player", (5, 1), LinkKind::Event, vec![1], 2 * S));
    assert!(b.event(2, 2 * S));
    meet(&mut a, &mut b, 3 * S);
    let copies = b.puts(3 * S);
    assert_eq!(a.hear(&copies, 3 * S, None), [Route::Held, Route::Held]);
    a.core.link_event_sent("B", None);
    a.release();
    assert_eq!(bodies(&a), [2]);
    let acks = a.puts(3 * S);
    b.hear(&acks, 3 * S, None);
    let f = b.core.take_failures();
    assert_eq!(f.len(), 1, "{f:?}");
    assert!(
        f[0].reason.contains(
            "refused on computer `A`: event from computer `B` claims origin `player`, which is computer `A`'s"
        ),
        "{f:?}"
    );
    assert_eq!(b.core.buffered("A"), 0);
    let e = a.counts("event");
    assert_eq!((e.from_link, e.refused), (2, 1));
}

#[test]
fn the_receiver_skips_what_its_sender_gave_up() {
    let (mut a, mut b) = (Side::new("A", 1), Side::new("B", 2));
    meet(&mut a, &mut b, 0);
    b.event(1, 0);
    let lost = b.puts(0);
    assert_eq!(lost.len(), 1);
    // 1 never arrives (every copy lost) and is given up at 10 s; 2, taken at 8 s, goes on.
    run(&mut a, &mut b, 8 * S);
    b.event(2, 8 * S);
    let copies: Vec<LinkMsg> = b
        .puts(8 * S)
        .into_iter()
        .filter(|m| m.body != [1])
        .collect();
    let routes = a.hear(&copies, 8 * S, None);
    assert_eq!(routes, [Route::Discarded], "1 is missing");
    run(&mut a, &mut b, 10 * S);
    assert_eq!(b.core.take_failures().len(), 1);
    let again = b.puts(10 * S);
    assert_eq!(
        again[0].carried.as_ref().map(|c| (c.seq, c.floor)),
        Some((2, 2))
    );
    assert_eq!(a.hear(&again, 10 * S, None), [Route::Deliver]);
    assert_eq!(bodies(&a), [2]);
}

#[test]
fn an_acknowledged_message_leaves_the_buffer_even_behind_one_too_old_to_send() {
    let (mut a, mut b) = (Side::new("A", 1), Side::new("B", 2));
    meet(&mut a, &mut b, 0);
    a.at(2 * S);
    b.at(2 * S);
    // Taken while A is lost: never sent, and too old to be sent once A is back at 11.2 s.
    b.event(1, 2 * S);
    a.at(11 * S + S / 5);
    b.at(11 * S + S / 5);
    meet(&mut a, &mut b, 11 * S + S / 5);
    b.event(2, 11 * S + S / 5);
    let copies = b.puts(11 * S + S / 5);
    assert_eq!(copies.len(), 1, "only the second");
    a.hear(&copies, 11 * S + S / 5, None);
    a.core.link_event_sent("B", None);
    a.release();
    assert_eq!(bodies(&a), [2]);
    let acks = a.puts(11 * S + S / 5);
    b.hear(&acks, 11 * S + S / 5, None);
    assert_eq!(b.core.buffered("A"), 1, "the second left, acknowledged");
    assert_eq!(b.counts("event").carried, 1);
    // The link goes again: the first is given up at 12 s, and nothing else ever.
    b.at(25 * S);
    let f = b.core.take_failures();
    assert_eq!(f.len(), 1, "{f:?}");
    assert_eq!(f[0].msg.body, [1]);
}
