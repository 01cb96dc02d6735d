//! The recent submissions as an Atom 1.0 feed (RFC 4287), for feed readers. Written by hand:
//! a feed is a few fixed elements, and no XML crate is among the checked dependencies. Every
//! text goes through [`text`], which escapes markup and leaves out the characters XML 1.0
//! cannot carry, so a method name can never break the document.

use std::fmt::Write;

use crate::service::catalogue::Recent;
use crate::wording;

/// The feed of `entries` (newest first) of the service at `site` (its absolute address, no
/// trailing slash). `now` (epoch ms) dates a feed with no entry.
pub fn atom(site: &str, entries: &[Recent], now: i64) -> String {
    let updated = entries
        .iter()
        .map(|e| e.finished_at.unwrap_or(e.created_at))
        .max()
        .unwrap_or(now);
    let mut out = String::new();
    out.push_str("<?xml version=\"1.0\" encoding=\"utf-8\"?>\n");
    out.push_str("<feed xmlns=\"http://www.w3.org/2005/Atom\">\n");
    let _ = writeln!(out, "  <id>{}</id>", text(&format!("{site}/submissions")));
    out.push_str("  <title>poseboard: recent submissions</title>\n");
    let _ = writeln!(out, "  <updated>{}</updated>", wording::rfc3339(updated));
    out.push_str("  <author><name>poseboard</name></author>\n");
    let _ = writeln!(
        out,
        "  <link rel=\"self\" type=\"application/atom+xml\" href=\"{}\"/>",
        text(&format!("{site}/submissions.atom"))
    );
    let _ = writeln!(
        out,
        "  <link rel=\"alternate\" type=\"text/html\" href=\"{}\"/>",
        text(&format!("{site}/submissions"))
    );
    for e in entries {
        let url = format!("{site}/submissions/{}", e.id);
        out.push_str("  <entry>\n");
        let _ = writeln!(out, "    <id>{}</id>", text(&url));
        let _ = writeln!(out, "    <title>{}</title>", text(&title(e)));
        let _ = writeln!(
            out,
            "    <updated>{}</updated>",
            wording::rfc3339(e.finished_at.unwrap_or(e.created_at))
        );
        let _ = writeln!(
            out,
            "    <published>{}</published>",
            wording::rfc3339(e.created_at)
        );
        if !e.owner.is_empty() {
            let _ = writeln!(out, "    <author><name>{}</name></author>", text(&e.owner));
        }
        let _ = writeln!(
            out,
            "    <link rel=\"alternate\" type=\"text/html\" href=\"{}\"/>",
            text(&url)
        );
        let _ = writeln!(out, "    <summary>{}</summary>", text(&summary(e)));
        out.push_str("  </entry>\n");
    }
    out.push_str("</feed>\n");
    out
}

/// "method – dataset – task by owner", as the recent list says it.
pub fn title(e: &Recent) -> String {
    let dataset = evaluator::dataset::display_name(&e.dataset);
    let by = if e.owner.is_empty() {
        String::new()
    } else {
        format!(" by {}", e.owner)
    };
    format!("{} – {dataset} – {}{by}", e.method, e.task)
}

/// The score and the date, in words: "bop19 AR 63.2 %, submitted 2026-12-02 15:10 UTC".
fn summary(e: &Recent) -> String {
    let score = match &e.score {
        Some(h) => format!("{} {} {:.1} %", h.board.as_str(), h.name, h.value * 100.0),
        None => "no score".to_string(),
    };
    format!("{score}, submitted {}", wording::utc_minute(e.created_at))
}

/// `s` as XML character data or an attribute value: markup escaped, and the characters XML
/// 1.0 does not allow (control characters but tab and line breaks, U+FFFE, U+FFFF) left out.
pub fn text(s: &str) -> String {
    let mut out = String::with_capacity(s.len());
    for c in s.chars() {
        match c {
            '&' => out.push_str("&amp;"),
            '<' => out.push_str("&lt;"),
            '>' => out.push_str("&gt;"),
            '"' => out.push_str("&quot;"),
            '\'' => out.push_str("&apos;"),
            '\t' | '\n' | '\r' => out.push(c),
            c if c < ' ' || c == '\u{FFFE}' || c == '\u{FFFF}' => {}
            c => out.push(c),
        }
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn text_escapes_markup_and_drops_what_xml_cannot_carry() {
        assert_eq!(
            text("R&D <net> \"a\" 'b'\u{1}\u{FFFF}\tx"),
            "R&amp;D &lt;net&gt; &quot;a&quot; &apos;b&apos;\tx"
        );
        assert_eq!(text("Café ✓"), "Café ✓");
    }
}
