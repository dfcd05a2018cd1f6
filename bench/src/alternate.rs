//! Measuring several set-ups in alternating blocks, so that their ratios compare the same
//! minutes of the machine.
//!
//! On a shared machine the state of the CPUs (idle and slow to wake, or busy with someone
//! else's work) changes within seconds: two set-ups measured one after the other may see two
//! different machines, and their ratio says more about the machine than about them. Here every
//! set-up is started and warmed up once, then they take turns: each measures a block of rounds
//! while the others are paused (a paused set-up runs nothing: no busy poll, no timer), and the
//! turns go round until every set-up has its rounds. Each keeps one histogram of all its
//! rounds and the summary of each block, so that a ratio can also be read block by block.

use std::time::{Duration, Instant};

use crate::roles::Res;
use crate::stats::{Latencies, Summary};

/// One set-up measured in blocks: its processes are started (and warmed up) before the first
/// block and stay up between blocks.
pub trait Side {
    /// Runs up to `n` round trips, recording each into `into` when given, and stops before a
    /// round that would start after `until`; returns the rounds done.
    fn rounds(
        &mut self,
        n: usize,
        into: Option<&mut Latencies>,
        until: Option<Instant>,
    ) -> Res<usize>;
    /// Makes sure nothing of it runs until [`resume`](Self::resume) (a busy-polling peer would
    /// take a CPU from the set-up measured meanwhile; a timer would wake one).
    fn pause(&mut self) -> Res<()>;
    /// Lets it run again.
    fn resume(&mut self) -> Res<()>;
    /// Stops its processes and removes what they left.
    fn finish(self: Box<Self>) -> Res<()>;
}

/// How the blocks are cut.
#[derive(Clone, Debug)]
pub struct Plan {
    /// Rounds recorded per set-up, all blocks together.
    pub rounds: usize,
    /// Blocks per set-up.
    pub blocks: usize,
    /// Rounds at the start of every block, not recorded: after its pause a set-up finds its
    /// caches taken by the other set-ups and its paused peer just woken.
    pub block_warmup: usize,
    /// Time a set-up measures at most, all its blocks together (rounds past it are not done).
    pub max: Duration,
}

/// The sizes of the blocks `rounds` are cut into: `blocks` of them (fewer when there are
/// fewer rounds, at least one), differing by one at most, the larger first.
pub fn block_sizes(rounds: usize, blocks: usize) -> Vec<usize> {
    let n = blocks.clamp(1, rounds.max(1));
    (0..n)
        .map(|i| rounds / n + usize::from(i < rounds % n))
        .collect()
}

/// The order of the set-ups in turn `turn`: forwards, then backwards, and so on, so that
/// neighbours (the pairs of a goal) stay next to each other and each set-up follows the other
/// set-ups as often as it precedes them.
pub fn turn_order(turn: usize, sides: usize) -> Vec<usize> {
    if turn.is_multiple_of(2) {
        (0..sides).collect()
    } else {
        (0..sides).rev().collect()
    }
}

/// What one set-up measured.
#[derive(Clone, Debug)]
pub struct Alternated {
    /// All its recorded rounds (the blocks merged); `cut_short` counts the rounds not done.
    pub latencies: Latencies,
    /// Each block's summary, one per turn (empty, `count` 0, where it did not measure).
    pub blocks: Vec<Summary>,
}

/// Warms up a started set-up alone, then pauses it.
pub fn prepare(side: Res<Box<dyn Side>>, warmup: usize) -> Res<Box<dyn Side>> {
    let mut side = side?;
    let warmed = side.rounds(warmup, None, None).and_then(|_| side.pause());
    match warmed {
        Ok(()) => Ok(side),
        Err(e) => {
            let _ = side.finish();
            Err(e)
        }
    }
}

/// Measures prepared (warmed-up, paused) set-ups in alternating blocks, then finishes them.
/// A set-up that fails drops out (its result says why); the others go on.
pub fn alternate(sides: Vec<Res<Box<dyn Side>>>, plan: &Plan) -> Vec<Res<Alternated>> {
    let n = sides.len();
    let mut live: Vec<Option<Box<dyn Side>>> = Vec::with_capacity(n);
    let mut results: Vec<Res<Alternated>> = Vec::with_capacity(n);
    for s in sides {
        match s {
            Ok(side) => {
                live.push(Some(side));
                results.push(Ok(Alternated {
                    latencies: Latencies::new(),
                    blocks: Vec::new(),
                }));
            }
            Err(e) => {
                live.push(None);
                results.push(Err(e));
            }
        }
    }
    let mut spent = vec![Duration::ZERO; n];
    let mut done = vec![0usize; n];
    for (turn, &size) in block_sizes(plan.rounds, plan.blocks).iter().enumerate() {
        for k in turn_order(turn, n) {
            let (Some(side), Ok(acc)) = (live[k].as_mut(), results[k].as_mut()) else {
                continue;
            };
            let left = plan.max.saturating_sub(spent[k]);
            if left.is_zero() {
                acc.blocks.push(Summary::default());
                continue;
            }
            let mut lat = Latencies::new();
            let measured = side
                .resume()
                .and_then(|()| side.rounds(plan.block_warmup, None, None))
                .and_then(|_| {
                    let start = Instant::now();
                    let r = side.rounds(size, Some(&mut lat), Some(start + left));
                    spent[k] += start.elapsed();
                    r
                })
                .and_then(|d| side.pause().map(|()| d));
            match measured {
                Ok(d) => {
                    done[k] += d;
                    acc.blocks.push(lat.summary());
                    acc.latencies.merge(&lat);
                }
                Err(e) => {
                    results[k] = Err(e);
                    if let Some(side) = live[k].take() {
                        let _ = side.finish();
                    }
                }
            }
        }
    }
    for (k, side) in live.into_iter().enumerate() {
        let Some(side) = side else { continue };
        let finished = side.finish();
        if let Ok(acc) = results[k].as_mut() {
            acc.latencies.cut_short = (plan.rounds - done[k].min(plan.rounds)) as u64;
        }
        if let (Err(e), Ok(_)) = (finished, &results[k]) {
            results[k] = Err(e);
        }
    }
    results
}

/// The ratios `a / b` of the p50s of blocks measured in the same turn (turns where either did
/// not measure are left out).
pub fn block_ratios(a: &[Summary], b: &[Summary]) -> Vec<f64> {
    a.iter()
        .zip(b)
        .filter(|(x, y)| x.count > 0 && y.count > 0 && x.p50 > 0.0 && y.p50 > 0.0)
        .map(|(x, y)| x.p50 / y.p50)
        .collect()
}

/// How per-block ratios spread, against a goal of at most `goal`.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Spread {
    /// Blocks compared.
    pub n: usize,
    /// Their median ratio (the mean of the two middle ones for an even count).
    pub median: f64,
    /// The smallest.
    pub min: f64,
    /// The largest.
    pub max: f64,
    /// Blocks whose ratio is at most the goal.
    pub within: usize,
}

/// The spread of `ratios` against `goal`; `None` when there is none.
pub fn spread(ratios: &[f64], goal: f64) -> Option<Spread> {
    if ratios.is_empty() {
        return None;
    }
    let mut r = ratios.to_vec();
    r.sort_by(f64::total_cmp);
    let n = r.len();
    let median = if n % 2 == 1 {
        r[n / 2]
    } else {
        (r[n / 2 - 1] + r[n / 2]) / 2.0
    };
    Some(Spread {
        n,
        median,
        min: r[0],
        max: r[n - 1],
        within: r.iter().filter(|&&x| x <= goal).count(),
    })
}

#[cfg(test)]
mod tests {
    use super::*;
    use std::cell::RefCell;
    use std::rc::Rc;

    #[test]
    fn blocks_cover_every_round_and_differ_by_one_at_most() {
        assert_eq!(block_sizes(20_000, 20), vec![1000; 20]);
        assert_eq!(block_sizes(300, 5), vec![60; 5]);
        assert_eq!(block_sizes(10, 4), vec![3, 3, 2, 2]);
        // Fewer rounds than blocks: one round a block, no empty block.
        assert_eq!(block_sizes(3, 20), vec![1, 1, 1]);
        assert_eq!(block_sizes(7, 0), vec![7]);
        assert_eq!(block_sizes(0, 5), vec![0]);
        for (rounds, blocks) in [(1001, 20), (299, 7), (5, 5)] {
            let s = block_sizes(rounds, blocks);
            assert_eq!(s.iter().sum::<usize>(), rounds);
            let (lo, hi) = (s.iter().min(), s.iter().max());
            assert!(hi.zip(lo).is_some_and(|(h, l)| h - l <= 1), "{s:?}");
        }
    }

    #[test]
    fn turns_go_forwards_then_backwards() {
        assert_eq!(turn_order(0, 4), vec![0, 1, 2, 3]);
        assert_eq!(turn_order(1, 4), vec![3, 2, 1, 0]);
        assert_eq!(turn_order(2, 4), vec![0, 1, 2, 3]);
        assert!(turn_order(3, 0).is_empty());
    }

    #[test]
    fn the_spread_says_how_many_blocks_meet_the_goal() {
        let s = spread(&[3.2, 2.8, 2.9, 3.0], 3.0).expect("some");
        assert_eq!(s.n, 4);
        assert!((s.median - 2.95).abs() < 1e-12, "{s:?}");
        assert_eq!((s.min, s.max, s.within), (2.8, 3.2, 3));
        let odd = spread(&[1.5, 0.9, 1.1], 1.0).expect("some");
        assert_eq!((odd.median, odd.within), (1.1, 1));
        assert_eq!(spread(&[], 1.0), None);
    }

    #[test]
    fn block_ratios_pair_blocks_of_the_same_turn() {
        let b = |p50: f64, count: u64| Summary {
            count,
            p50,
            ..Summary::default()
        };
        let a = [b(3.0, 10), b(0.0, 0), b(4.0, 10), b(5.0, 10)];
        let base = [b(1.0, 10), b(1.0, 10), b(2.0, 10)];
        // The second turn is skipped (a did not measure), the fourth has no partner.
        assert_eq!(block_ratios(&a, &base), vec![3.0, 2.0]);
    }

    /// A set-up whose rounds take a fixed time, logging what the driver asks of it.
    struct Fake {
        name: char,
        ns: u64,
        fail_at_turn: Option<usize>,
        log: Rc<RefCell<String>>,
        turns: usize,
        running: bool,
    }

    impl Side for Fake {
        fn rounds(
            &mut self,
            n: usize,
            into: Option<&mut Latencies>,
            _until: Option<Instant>,
        ) -> Res<usize> {
            if !self.running && into.is_some() {
                return Err(format!("{} measured while paused", self.name));
            }
            if let Some(l) = into {
                if self.fail_at_turn == Some(self.turns) {
                    return Err(format!("{} broke", self.name));
                }
                self.turns += 1;
                self.log.borrow_mut().push(self.name);
                for _ in 0..n {
                    l.record_ns(self.ns);
                }
            }
            Ok(n)
        }
        fn pause(&mut self) -> Res<()> {
            self.running = false;
            Ok(())
        }
        fn resume(&mut self) -> Res<()> {
            self.running = true;
            Ok(())
        }
        fn finish(self: Box<Self>) -> Res<()> {
            self.log.borrow_mut().push('.');
            Ok(())
        }
    }

    fn fake(
        name: char,
        ns: u64,
        fail_at_turn: Option<usize>,
        log: &Rc<RefCell<String>>,
    ) -> Res<Box<dyn Side>> {
        prepare(
            Ok(Box::new(Fake {
                name,
                ns,
                fail_at_turn,
                log: log.clone(),
                turns: 0,
                running: true,
            })),
            5,
        )
    }

    fn plan(rounds: usize, blocks: usize) -> Plan {
        Plan {
            rounds,
            blocks,
            block_warmup: 2,
            max: Duration::from_secs(60),
        }
    }

    #[test]
    fn sides_take_turns_and_keep_their_own_histograms() {
        let log = Rc::new(RefCell::new(String::new()));
        let sides = vec![
            fake('a', 1000, None, &log),
            fake('b', 3000, None, &log),
            Err("c could not start".to_owned()),
        ];
        let r = alternate(sides, &plan(100, 4));
        // Turns alternate a b, b a, ...; each finished once at the end.
        assert_eq!(log.borrow().as_str(), "abbaabba..");
        let a = r[0].as_ref().expect("a measured");
        let b = r[1].as_ref().expect("b measured");
        assert_eq!((a.latencies.len(), a.latencies.cut_short), (100, 0));
        assert_eq!(b.latencies.len(), 100);
        assert_eq!(a.blocks.len(), 4);
        assert!(a.blocks.iter().all(|s| s.count == 25));
        let ratios = block_ratios(&b.blocks, &a.blocks);
        assert_eq!(ratios.len(), 4);
        assert!(ratios.iter().all(|x| (x - 3.0).abs() < 0.01), "{ratios:?}");
        assert_eq!(
            r[2].as_ref().err().map(String::as_str),
            Some("c could not start")
        );
    }

    #[test]
    fn a_failing_side_drops_out_and_the_others_go_on() {
        let log = Rc::new(RefCell::new(String::new()));
        let sides = vec![fake('a', 1000, Some(1), &log), fake('b', 2000, None, &log)];
        let r = alternate(sides, &plan(60, 3));
        // a measures its first block, fails in the second turn and is finished there.
        assert_eq!(log.borrow().as_str(), "abb.b.");
        assert_eq!(r[0].as_ref().err().map(String::as_str), Some("a broke"));
        let b = r[1].as_ref().expect("b measured");
        assert_eq!((b.latencies.len(), b.blocks.len()), (60, 3));
    }
}
