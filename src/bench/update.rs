//! Replacing one suite's generated section of a markdown file (BENCHMARKS.md).
//!
//! The section is delimited by `<!-- bench:SUITE:begin -->` and
//! `<!-- bench:SUITE:end -->`; everything between the markers is generated,
//! everything outside them is the author's and is kept byte for byte. A file
//! without the markers gets the section appended. Malformed markers (one
//! without the other, out of order, repeated) are an error rather than a
//! guess, so hand-written text is never overwritten.

#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
pub enum SectionError {
    #[error("has '{marker}' {count} times (expected once)")]
    Repeated { marker: String, count: usize },
    #[error("has '{present}' but not '{missing}'")]
    Unpaired { present: String, missing: String },
    #[error("has '{end}' before '{begin}'")]
    OutOfOrder { begin: String, end: String },
}

pub fn begin_marker(suite: &str) -> String {
    format!("<!-- bench:{suite}:begin -->")
}

pub fn end_marker(suite: &str) -> String {
    format!("<!-- bench:{suite}:end -->")
}

/// Where the current section's content lies (between the markers), if the
/// document has one; checks the markers either way.
fn locate(doc: &str, suite: &str) -> Result<Option<(usize, usize)>, SectionError> {
    let (begin, end) = (begin_marker(suite), end_marker(suite));
    for m in [&begin, &end] {
        let count = doc.matches(m.as_str()).count();
        if count > 1 {
            return Err(SectionError::Repeated {
                marker: m.clone(),
                count,
            });
        }
    }
    match (doc.find(&begin), doc.find(&end)) {
        (None, None) => Ok(None),
        (Some(_), None) => Err(SectionError::Unpaired {
            present: begin,
            missing: end,
        }),
        (None, Some(_)) => Err(SectionError::Unpaired {
            present: end,
            missing: begin,
        }),
        (Some(b), Some(e)) if e < b => Err(SectionError::OutOfOrder { begin, end }),
        (Some(b), Some(e)) => Ok(Some((b + begin.len(), e))),
    }
}

/// Checks that `doc` can take a section for `suite` (before a long run).
pub fn check(doc: &str, suite: &str) -> Result<(), SectionError> {
    locate(doc, suite).map(|_| ())
}

/// `doc` with the section of `suite` holding `body` (replaced or appended).
pub fn replace_section(doc: &str, suite: &str, body: &str) -> Result<String, SectionError> {
    let body = body.trim_matches('\n');
    match locate(doc, suite)? {
        Some((start, end)) => Ok(format!("{}\n{body}\n{}", &doc[..start], &doc[end..])),
        None => {
            let mut out = doc.to_string();
            if !out.is_empty() && !out.ends_with('\n') {
                out.push('\n');
            }
            if !out.is_empty() {
                out.push('\n');
            }
            out.push_str(&format!(
                "{}\n{body}\n{}\n",
                begin_marker(suite),
                end_marker(suite)
            ));
            Ok(out)
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn replaces_only_between_the_markers() {
        let doc = "# Bench\n\nintro\n\n<!-- bench:quick:begin -->\nold\ntable\n<!-- bench:quick:end -->\n\n\
                   <!-- bench:paper:begin -->\npaper\n<!-- bench:paper:end -->\ntail\n";
        let out = replace_section(doc, "quick", "\nnew table\n").unwrap();
        assert_eq!(
            out,
            "# Bench\n\nintro\n\n<!-- bench:quick:begin -->\nnew table\n<!-- bench:quick:end -->\n\n\
             <!-- bench:paper:begin -->\npaper\n<!-- bench:paper:end -->\ntail\n"
        );
        // Idempotent: the same body again changes nothing.
        assert_eq!(replace_section(&out, "quick", "new table").unwrap(), out);
        // Empty sections (as in a fresh BENCHMARKS.md) fill in.
        let empty = "<!-- bench:full:begin -->\n<!-- bench:full:end -->\n";
        assert_eq!(
            replace_section(empty, "full", "t").unwrap(),
            "<!-- bench:full:begin -->\nt\n<!-- bench:full:end -->\n"
        );
    }

    #[test]
    fn appends_when_absent() {
        assert_eq!(
            replace_section("# B\nintro", "quick", "t").unwrap(),
            "# B\nintro\n\n<!-- bench:quick:begin -->\nt\n<!-- bench:quick:end -->\n"
        );
        assert_eq!(
            replace_section("", "quick", "t").unwrap(),
            "<!-- bench:quick:begin -->\nt\n<!-- bench:quick:end -->\n"
        );
        // Another suite's markers are not this suite's.
        let doc = "<!-- bench:paper:begin -->\np\n<!-- bench:paper:end -->\n";
        let out = replace_section(doc, "quick", "q").unwrap();
        assert!(out.starts_with(doc) && out.contains("<!-- bench:quick:begin -->\nq\n"));
    }

    #[test]
    fn refuses_malformed_markers() {
        let b = begin_marker("quick");
        let e = end_marker("quick");
        assert!(matches!(
            replace_section(&format!("{b}\nx\n"), "quick", "t"),
            Err(SectionError::Unpaired { .. })
        ));
        assert!(matches!(
            replace_section(&format!("x\n{e}\n"), "quick", "t"),
            Err(SectionError::Unpaired { .. })
        ));
        assert!(matches!(
            replace_section(&format!("{e}\n{b}\n"), "quick", "t"),
            Err(SectionError::OutOfOrder { .. })
        ));
        assert!(matches!(
            replace_section(&format!("{b}\n{e}\n{b}\n{e}\n"), "quick", "t"),
            Err(SectionError::Repeated { count: 2, .. })
        ));
        assert!(check(&format!("{e}\n{b}\n"), "quick").is_err());
        assert!(check("plain", "quick").is_ok());
    }
}
