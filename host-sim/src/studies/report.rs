//! The one writer of what the studies leave behind: Markdown tables (head and rule), the
//! generated sections of the docs (between two marker comments), and files written with
//! their path in the error.

use std::path::Path;

/// A Markdown table's head: `| a | b |` and its `|---|---|` rule, each on its own line.
pub fn table_head<S: AsRef<str>>(columns: impl IntoIterator<Item = S>) -> String {
    let (mut head, mut rule) = (String::from("|"), String::from("|"));
    for c in columns {
        head.push(' ');
        head.push_str(c.as_ref());
        head.push_str(" |");
        rule.push_str("---|");
    }
    format!("{head}\n{rule}\n")
}

/// `doc` with what lies between the markers `begin` and `end` replaced by `text` (on lines of
/// its own). `what` names the markers in the error when they are out of order.
pub fn replace_between(
    doc: &str,
    (begin, end): (&str, &str),
    text: &str,
    what: &str,
) -> Result<String, String> {
    let (Some(b), Some(e)) = (doc.find(begin), doc.find(end)) else {
        return Err(format!("the document has no '{begin}' ... '{end}' section"));
    };
    if e < b {
        return Err(format!("{what} markers out of order"));
    }
    Ok(format!(
        "{}\n{}\n{}",
        &doc[..b + begin.len()],
        text.trim_matches('\n'),
        &doc[e..]
    ))
}

/// Write `bytes` to `path`; the error names the path.
pub fn write_file(path: &Path, bytes: impl AsRef<[u8]>) -> Result<(), String> {
    std::fs::write(path, bytes).map_err(|e| format!("{}: {e}", path.display()))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_head_has_one_rule_cell_per_column() {
        assert_eq!(table_head(["a", "b c"]), "| a | b c |\n|---|---|\n");
    }

    #[test]
    fn markers_out_of_order_are_an_error() {
        let e = replace_between("E B", ("B", "E"), "x", "table").unwrap_err();
        assert_eq!(e, "table markers out of order");
    }
}
