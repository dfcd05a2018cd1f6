//! Latency histograms (HDR, nanoseconds) and their summaries.

use hdrhistogram::Histogram;
use std::time::Duration;

/// The latencies of one measurement, warm-up excluded.
#[derive(Clone, Debug)]
pub struct Latencies {
    hist: Histogram<u64>,
    /// Rounds that were asked for but not done within the measurement's time limit.
    pub cut_short: u64,
}

/// Percentiles of a [`Latencies`], in microseconds.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct Summary {
    /// Samples.
    pub count: u64,
    /// Median.
    pub p50: f64,
    /// 90th percentile.
    pub p90: f64,
    /// 99th percentile.
    pub p99: f64,
    /// 99.9th percentile.
    pub p999: f64,
    /// Largest.
    pub max: f64,
}

impl Default for Latencies {
    fn default() -> Self {
        Self::new()
    }
}

impl Latencies {
    /// An empty histogram from 1 ns to 100 s, three significant digits.
    pub fn new() -> Self {
        Latencies {
            // 1 ns to 100 s at 3 digits is a valid configuration: the constructor cannot fail.
            hist: Histogram::new_with_bounds(1, 100_000_000_000, 3)
                .expect("1 ns to 100 s at 3 digits is a valid hdrhistogram configuration"),
            cut_short: 0,
        }
    }

    /// Records one sample (clamped to the histogram's range).
    pub fn record(&mut self, d: Duration) {
        self.record_ns(d.as_nanos().min(u128::from(u64::MAX)) as u64);
    }

    /// Records one sample given in nanoseconds.
    pub fn record_ns(&mut self, ns: u64) {
        self.hist.saturating_record(ns.max(1));
    }

    /// Adds another measurement's samples.
    pub fn merge(&mut self, other: &Latencies) {
        // Same bounds on both sides: adding cannot fail but for a count overflow.
        let _ = self.hist.add(&other.hist);
        self.cut_short += other.cut_short;
    }

    /// Samples recorded.
    pub fn len(&self) -> u64 {
        self.hist.len()
    }

    /// The percentiles, in microseconds.
    pub fn summary(&self) -> Summary {
        if self.hist.is_empty() {
            return Summary::default();
        }
        let us = |q: f64| self.hist.value_at_quantile(q) as f64 / 1000.0;
        Summary {
            count: self.hist.len(),
            p50: us(0.5),
            p90: us(0.9),
            p99: us(0.99),
            p999: us(0.999),
            max: self.hist.max() as f64 / 1000.0,
        }
    }

    /// The cumulative distribution as (microseconds, fraction of samples at or below), for
    /// plotting: one point per distinct recorded value bucket.
    pub fn cdf(&self) -> Vec<(f64, f64)> {
        let total = self.hist.len() as f64;
        if total == 0.0 {
            return Vec::new();
        }
        let mut out = Vec::new();
        for v in self.hist.iter_recorded() {
            out.push((
                v.value_iterated_to() as f64 / 1000.0,
                v.count_since_last_iteration() as f64 / total,
            ));
        }
        // iter_recorded gives counts per bucket: accumulate.
        let mut acc = 0.0;
        for p in &mut out {
            acc += p.1;
            p.1 = acc.min(1.0);
        }
        out
    }

    /// The samples as text (`value count` pairs), to pass between processes.
    pub fn to_text(&self) -> String {
        let mut s = format!("cut_short {}\n", self.cut_short);
        for v in self.hist.iter_recorded() {
            s.push_str(&format!(
                "{} {}\n",
                v.value_iterated_to(),
                v.count_at_value()
            ));
        }
        s
    }

    /// Reads what [`to_text`](Self::to_text) wrote.
    pub fn from_text(text: &str) -> Result<Self, String> {
        let mut l = Latencies::new();
        for (i, line) in text.lines().enumerate() {
            let mut it = line.split_whitespace();
            let (Some(a), Some(b)) = (it.next(), it.next()) else {
                continue;
            };
            let bad = || format!("line {}: `{line}` is not `value count`", i + 1);
            if a == "cut_short" {
                l.cut_short = b.parse().map_err(|_| bad())?;
                continue;
            }
            let v: u64 = a.parse().map_err(|_| bad())?;
            let n: u64 = b.parse().map_err(|_| bad())?;
            l.hist
                .record_n(v.max(1), n)
                .map_err(|e| format!("line {}: {e:?}", i + 1))?;
        }
        Ok(l)
    }
}

/// A ratio `a / b` as text ("2.3x"), or "-" when either side is missing.
pub fn ratio(a: f64, b: f64) -> String {
    if a > 0.0 && b > 0.0 {
        let r = a / b;
        if r >= 10.0 {
            format!("{r:.0}x")
        } else if r >= 0.1 {
            format!("{r:.1}x")
        } else {
            // A figure far below its baseline still says how far.
            format!("{r:.3}x")
        }
    } else {
        "-".to_owned()
    }
}

/// Microseconds as text with sensible precision.
pub fn us(v: f64) -> String {
    if v == 0.0 {
        "-".to_owned()
    } else if v < 10.0 {
        format!("{v:.2}")
    } else if v < 1000.0 {
        format!("{v:.1}")
    } else {
        format!("{v:.0}")
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn percentiles_follow_the_samples() {
        let mut l = Latencies::new();
        for i in 1..=1000u64 {
            l.record_ns(i * 1000);
        }
        let s = l.summary();
        assert_eq!(s.count, 1000);
        assert!((s.p50 - 500.0).abs() < 1.0, "{s:?}");
        assert!((s.p99 - 990.0).abs() < 1.0, "{s:?}");
        assert!((s.max - 1000.0).abs() < 1.0, "{s:?}");
        let cdf = l.cdf();
        assert!((cdf.last().map(|p| p.1).unwrap_or(0.0) - 1.0).abs() < 1e-9);
    }

    #[test]
    fn text_round_trip_keeps_the_distribution() {
        let mut l = Latencies::new();
        for i in [3u64, 50, 50, 7000, 123_456] {
            l.record_ns(i);
        }
        l.cut_short = 2;
        let back = Latencies::from_text(&l.to_text()).expect("reads back");
        assert_eq!(back.summary(), l.summary());
        assert_eq!(back.cut_short, 2);
        assert!(Latencies::from_text("x y").is_err());
    }
}
