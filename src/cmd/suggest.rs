//! "Did you mean ...?": for an address the daemon does not know, the nearest one of those
//! docs/osc.md lists (its "Addresses" tables are the reference, read here at build time, so
//! a new address documented there is suggested without a second list to keep).

use std::sync::OnceLock;

/// The reference the suggestions come from.
const REFERENCE: &str = include_str!("../../docs/osc.md");

/// The command addresses of the reference's "Addresses" section: each table row's first
/// cell, `<...>` marking a segment that stands for a name or a number.
fn known() -> &'static [&'static str] {
    static KNOWN: OnceLock<Vec<&'static str>> = OnceLock::new();
    KNOWN.get_or_init(|| {
        let start = REFERENCE.find("\n## Addresses").unwrap_or(0);
        let end = REFERENCE[start + 1..]
            .find("\n## ")
            .map_or(REFERENCE.len(), |e| start + 1 + e);
        let mut out: Vec<&str> = REFERENCE[start..end]
            .lines()
            .filter_map(|l| l.strip_prefix("| `"))
            .filter_map(|l| l.split(['`', ' ']).next())
            .filter(|a| a.starts_with("/vo/"))
            .collect();
        out.sort_unstable();
        out.dedup();
        out
    })
}

/// The known address nearest `path` (lowercase, as received without its trailing numbers),
/// if one is near enough to be what was meant: a few letters off, a segment missing or
/// swapped. A `<...>` segment takes the sent segment in its place.
pub fn nearest(path: &str) -> Option<String> {
    let sent: Vec<&str> = path.split('/').collect();
    let mut best: Option<(usize, String)> = None;
    for pattern in known() {
        let parts: Vec<&str> = pattern.split('/').collect();
        let candidate = if parts.len() == sent.len() {
            parts
                .iter()
                .zip(&sent)
                .map(|(p, s)| if p.starts_with('<') { *s } else { *p })
                .collect::<Vec<_>>()
                .join("/")
        } else {
            (*pattern).to_string()
        };
        let d = strsim::levenshtein(path, &candidate);
        if best.as_ref().is_none_or(|(b, _)| d < *b) {
            best = Some((d, candidate));
        }
    }
    let (d, candidate) = best?;
    (d > 0 && d <= (path.len() / 4).max(2)).then_some(candidate)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_reference_lists_the_addresses() {
        let known = known();
        for a in [
            "/vo/pick",
            "/vo/generate",
            "/vo/light/<ch>/level",
            "/vo/reload",
        ] {
            assert!(known.contains(&a), "{a} not in {known:?}");
        }
        // Pushes are not commands.
        assert!(!known.contains(&"/vo/status/text"), "{known:?}");
    }

    #[test]
    fn a_near_miss_gets_the_address_meant() {
        assert_eq!(nearest("/vo/pikc").as_deref(), Some("/vo/pick"));
        assert_eq!(nearest("/vo/genrate").as_deref(), Some("/vo/generate"));
        assert_eq!(
            nearest("/vo/light/7/levle").as_deref(),
            Some("/vo/light/7/level")
        );
        assert_eq!(
            nearest("/vo/objectives/add").as_deref(),
            Some("/vo/objective/add")
        );
        assert_eq!(nearest("/totally/else/entirely"), None);
    }
}
