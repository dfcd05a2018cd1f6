//! "Did you mean" hints, shared by every checker of a project's files (the nets and manifest
//! in petrel-nets, `can.toml` in the CAN data server, `vehicle.toml` in the CLI), so that a
//! misspelt name gets the same help wherever it is written.

/// How a hint speaks of the names a misspelt one was looked for among: the user can fix a
/// declared name in the project, but not the names a DBC or a fixed list gives.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Candidates {
    /// Names the project declares (nets, places, events, programs...): "none is declared",
    /// "the declared ones are ...".
    Declared,
    /// Names from elsewhere (a DBC's messages and signals, rule kinds, bus states): "there is
    /// none", "the known ones are ...".
    Known,
}

/// Edit distance (Levenshtein, over characters) between two names.
pub fn distance(a: &str, b: &str) -> usize {
    let b: Vec<char> = b.chars().collect();
    let mut row: Vec<usize> = (0..=b.len()).collect();
    for (i, ca) in a.chars().enumerate() {
        let mut prev = row[0];
        row[0] = i + 1;
        for (j, cb) in b.iter().enumerate() {
            let cur = row[j + 1];
            row[j + 1] = (prev + usize::from(ca != *cb)).min(row[j] + 1).min(cur + 1);
            prev = cur;
        }
    }
    row[b.len()]
}

/// The hint for `name`, which is none of `candidates`: "did you mean `x`?" when one is close
/// (ignoring case; the alphabetically first among equally close ones), else the candidates when
/// there are few enough to read, else their number.
pub fn suggest<'a>(
    name: &str,
    candidates: impl IntoIterator<Item = &'a str>,
    wording: Candidates,
) -> String {
    let all: Vec<&str> = candidates.into_iter().collect();
    let best = all
        .iter()
        .map(|c| (distance(&name.to_lowercase(), &c.to_lowercase()), *c))
        .min();
    let (none, some, many) = match wording {
        Candidates::Declared => ("none is declared", "the declared ones are", "are declared"),
        Candidates::Known => ("there is none", "the known ones are", "are known"),
    };
    match best {
        Some((d, c)) if d <= 2.max(name.len() / 3) => format!("did you mean `{c}`?"),
        _ if all.is_empty() => none.to_owned(),
        _ if all.len() <= 8 => format!(
            "{some} {}",
            all.iter()
                .map(|c| format!("`{c}`"))
                .collect::<Vec<_>>()
                .join(", ")
        ),
        _ => format!("{} {many}; check the spelling", all.len()),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn suggestions_find_near_names() {
        assert_eq!(
            suggest("rolin", ["rolling", "climb"], Candidates::Declared),
            "did you mean `rolling`?"
        );
        assert!(suggest("zzz", ["a", "b"], Candidates::Declared).contains("`a`, `b`"));
        assert_eq!(distance("kitten", "sitting"), 3);
    }

    #[test]
    fn the_wording_follows_where_the_names_come_from() {
        let many: Vec<String> = (0..9).map(|i| format!("name{i}")).collect();
        let many = || many.iter().map(String::as_str);
        for (wording, none, few, lots) in [
            (
                Candidates::Declared,
                "none is declared",
                "the declared ones are `a`, `b`",
                "9 are declared; check the spelling",
            ),
            (
                Candidates::Known,
                "there is none",
                "the known ones are `a`, `b`",
                "9 are known; check the spelling",
            ),
        ] {
            assert_eq!(suggest("zzz", [], wording), none);
            assert_eq!(suggest("zzz", ["a", "b"], wording), few);
            assert_eq!(suggest("zzzzzzz", many(), wording), lots);
        }
    }

    #[test]
    fn case_is_ignored_and_ties_go_to_the_first_in_order() {
        assert_eq!(
            suggest("DEPTH", ["depth", "Depths"], Candidates::Known),
            "did you mean `depth`?"
        );
        assert_eq!(
            suggest("ab", ["ax", "ay"], Candidates::Known),
            "did you mean `ax`?"
        );
    }
}
