//! Durations as Petrel's files write them: a number and a unit, `200ms`, `30s`, `1.5min`, `2h`.
//!
//! One table of units ([`TimeUnit`]) for both places durations are written: a net's timers
//! (`after 30s`, read by the lexer inside its number grammar, so `1_000ms` and `1e3s` read too,
//! and counted in milliseconds) and `can.toml`'s hold times and periods ([`parse_duration_us`]:
//! a whole TOML string, plainer, and also in microseconds, because a bus is timed finer than a
//! mission).

/// A unit of a duration literal.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum TimeUnit {
    /// Milliseconds, `ms`.
    Millis,
    /// Seconds, `s`.
    Seconds,
    /// Minutes, `min`.
    Minutes,
    /// Hours, `h`.
    Hours,
}

impl TimeUnit {
    /// Every unit.
    pub const ALL: [TimeUnit; 4] = [
        TimeUnit::Millis,
        TimeUnit::Seconds,
        TimeUnit::Minutes,
        TimeUnit::Hours,
    ];

    /// The unit written `suffix` (`ms`, `s`, `min`, `h`).
    pub fn from_suffix(suffix: &str) -> Option<TimeUnit> {
        Self::ALL.into_iter().find(|u| u.suffix() == suffix)
    }

    /// The suffix as written.
    pub fn suffix(self) -> &'static str {
        match self {
            TimeUnit::Millis => "ms",
            TimeUnit::Seconds => "s",
            TimeUnit::Minutes => "min",
            TimeUnit::Hours => "h",
        }
    }

    /// Milliseconds in one unit.
    pub fn millis(self) -> f64 {
        match self {
            TimeUnit::Millis => 1.0,
            TimeUnit::Seconds => 1e3,
            TimeUnit::Minutes => 60e3,
            TimeUnit::Hours => 3600e3,
        }
    }
}

/// The suffix of microseconds, which only [`parse_duration_us`] takes: a net's timers count
/// in milliseconds, so a net cannot write them.
pub const MICROS_SUFFIX: &str = "us";

/// Parses a duration written as a whole string, `can.toml`'s `for = "200ms"`: digits with an
/// optional fraction (`1.5s`, not `.5s`, `1.s` or `1e3s`), then a unit, `us` or one of
/// [`TimeUnit`]'s, into microseconds (rounded). `None` for anything else, a negative or a
/// non-finite value, or more than about 290,000 years.
pub fn parse_duration_us(text: &str) -> Option<u64> {
    let t = text.trim();
    let split = t
        .find(|c: char| !(c.is_ascii_digit() || c == '.'))
        .unwrap_or(t.len());
    let (number, unit) = t.split_at(split);
    let unit = unit.trim();
    // The products are exact in f64 (at most 3.6e9), so a unit reads the same here as in a net.
    let scale = if unit == MICROS_SUFFIX {
        1.0
    } else {
        TimeUnit::from_suffix(unit)?.millis() * 1e3
    };
    if number.is_empty() || number.starts_with('.') || number.ends_with('.') {
        return None;
    }
    let v: f64 = number.parse().ok()?;
    let us = (v * scale).round();
    (0.0..9.2e18).contains(&us).then_some(us as u64)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn durations_read_in_every_unit() {
        assert_eq!(parse_duration_us("200ms"), Some(200_000));
        assert_eq!(parse_duration_us("1.5s"), Some(1_500_000));
        assert_eq!(parse_duration_us("2min"), Some(120_000_000));
        assert_eq!(parse_duration_us("1h"), Some(3_600_000_000));
        assert_eq!(parse_duration_us("250us"), Some(250));
        for bad in [
            "", "ms", "10", "-1s", "1.s", ".5s", "1e3s", "5 days", "1e400s",
        ] {
            assert_eq!(parse_duration_us(bad), None, "{bad}");
        }
    }

    #[test]
    fn a_unit_means_what_it_means_in_a_net() {
        for u in TimeUnit::ALL {
            assert_eq!(TimeUnit::from_suffix(u.suffix()), Some(u));
            let us = parse_duration_us(&format!("3{}", u.suffix())).unwrap();
            assert_eq!(us as f64, 3.0 * u.millis() * 1e3, "{u:?}");
        }
        assert_eq!(TimeUnit::from_suffix(MICROS_SUFFIX), None);
        assert_eq!(TimeUnit::from_suffix("sec"), None);
    }

    #[test]
    fn spaces_around_and_before_the_unit_are_allowed() {
        assert_eq!(parse_duration_us(" 5 ms "), Some(5_000));
        assert_eq!(parse_duration_us("0.0005s"), Some(500));
    }
}
