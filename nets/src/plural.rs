//! Counts for people: "1 program", "0 timers", "2 processes", the one way every summary of
//! the command line and of the verifier writes a number of things.

/// `n` and the noun, plural unless `n` is one: `count(1, "program")` is "1 program",
/// `count(0, "timer")` "0 timers", `count(3, "entry")` "3 entries".
///
/// The noun is its singular; the plural is made by the regular English rules ([`plural`]). A
/// noun phrase takes the rule on its last word: `count(2, "timed send")` is "2 timed sends".
pub fn count(n: impl TryInto<u64> + Copy + std::fmt::Display, noun: &str) -> String {
    let one = n.try_into().is_ok_and(|v| v == 1);
    if one {
        format!("{n} {noun}")
    } else {
        format!("{n} {}", plural(noun))
    }
}

/// The regular English plural of `noun`: "process" → "processes", "entry" → "entries",
/// "delivery" → "deliveries", "key" → "keys", "program" → "programs".
pub fn plural(noun: &str) -> String {
    let lower = noun.to_ascii_lowercase();
    if ["s", "x", "z", "ch", "sh"]
        .iter()
        .any(|e| lower.ends_with(e))
    {
        return format!("{noun}es");
    }
    if let Some(stem) = noun.strip_suffix('y') {
        let before = stem.chars().last().map(|c| c.to_ascii_lowercase());
        if before.is_some_and(|c| !"aeiou".contains(c)) {
            return format!("{stem}ies");
        }
    }
    format!("{noun}s")
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn one_is_singular_and_every_other_count_plural() {
        assert_eq!(count(1usize, "program"), "1 program");
        assert_eq!(count(0usize, "timer"), "0 timers");
        assert_eq!(count(2u64, "timed send"), "2 timed sends");
        assert_eq!(count(1u32, "process"), "1 process");
        assert_eq!(count(2u32, "process"), "2 processes");
        assert_eq!(count(3usize, "entry"), "3 entries");
        assert_eq!(count(2usize, "event delivery"), "2 event deliveries");
        assert_eq!(count(2usize, "key"), "2 keys");
        assert_eq!(count(2usize, "match"), "2 matches");
        assert_eq!(count(-1i64, "error"), "-1 errors");
    }
}
