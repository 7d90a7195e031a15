//! Line/column arithmetic on the scene text, and finding where a value starts.
//!
//! ron reports an error at the last token it consumed. For a number that is the number itself;
//! for a string it is the first character inside the quotes; for a tuple or struct it is the
//! closing bracket. [`value_start`] turns all three into the first character of the value: the
//! opening quote, or the opening bracket (or the name before it, as in `Box(`).
//!
//! Lines and columns are 1-based and count characters (not bytes), like ron's.

/// Byte offset of 1-based (`line`, `col`), clamped to the text.
pub(super) fn offset_of(text: &str, line: usize, col: usize) -> usize {
    let mut cur_line = 1;
    let mut line_start = 0;
    if line > 1 {
        for (i, c) in text.char_indices() {
            if c == '\n' {
                cur_line += 1;
                if cur_line == line {
                    line_start = i + 1;
                    break;
                }
            }
        }
        if cur_line < line {
            return text.len();
        }
    }
    text[line_start..]
        .char_indices()
        .take_while(|&(_, c)| c != '\n')
        .nth(col.saturating_sub(1))
        .map_or_else(
            || {
                // One past the end of the line (ron reports end-of-input like that).
                line_start
                    + text[line_start..]
                        .find('\n')
                        .unwrap_or(text.len() - line_start)
            },
            |(i, _)| line_start + i,
        )
}

/// 1-based (line, column) of a byte offset.
pub(super) fn line_col(text: &str, offset: usize) -> (usize, usize) {
    let offset = offset.min(text.len());
    let before = &text[..offset];
    let line = 1 + before.matches('\n').count();
    let line_start = before.rfind('\n').map_or(0, |i| i + 1);
    let col = 1 + before[line_start..].chars().count();
    (line, col)
}

fn is_ident_char(c: char) -> bool {
    c.is_alphanumeric() || c == '_'
}

/// Where the value whose last token sits at byte `target` starts (see the module doc).
/// Anything that is not a closing bracket or inside a string is returned unchanged.
pub(super) fn value_start(text: &str, target: usize) -> usize {
    let b = text.as_bytes();
    let n = b.len();
    let mut stack: Vec<usize> = Vec::new();
    let mut i = 0;
    while i < n && i <= target {
        let c = b[i];
        match c {
            b'/' if b.get(i + 1) == Some(&b'/') => {
                while i < n && b[i] != b'\n' {
                    i += 1;
                }
            }
            b'/' if b.get(i + 1) == Some(&b'*') => i = skip_block_comment(b, i),
            b'"' => {
                let start = i;
                i = skip_string(b, i + 1);
                if target < i {
                    return start;
                }
            }
            b'r' | b'b' if starts_raw_or_byte_string(b, i) => {
                let start = i;
                i = skip_raw_or_byte_string(b, i);
                if target < i {
                    return start;
                }
            }
            b'\'' => i = skip_char(b, i),
            b'(' | b'[' | b'{' => {
                stack.push(i);
                i += 1;
            }
            b')' | b']' | b'}' => {
                let open = stack.pop();
                if i == target {
                    return open.map_or(target, |o| name_before(text, o));
                }
                i += 1;
            }
            _ if c.is_ascii_alphabetic() || c == b'_' => {
                while i < n && (b[i].is_ascii_alphanumeric() || b[i] == b'_') {
                    i += 1;
                }
            }
            _ => i += 1,
        }
    }
    target
}

/// The first number written in a way the scene format refuses but ron would read: hexadecimal,
/// octal or binary (`0x10`, ron reads 16 as an integer and a 0 followed by junk as a float),
/// or with `_` separators (`1_0`, read as 10). Returns its byte offset and the message.
/// Strings, comments and identifiers are skipped.
pub(super) fn non_decimal_number(text: &str) -> Option<(usize, String)> {
    let b = text.as_bytes();
    let n = b.len();
    let mut i = 0;
    while i < n {
        let c = b[i];
        match c {
            b'/' if b.get(i + 1) == Some(&b'/') => {
                while i < n && b[i] != b'\n' {
                    i += 1;
                }
            }
            b'/' if b.get(i + 1) == Some(&b'*') => i = skip_block_comment(b, i),
            b'"' => i = skip_string(b, i + 1),
            b'r' | b'b' if starts_raw_or_byte_string(b, i) => i = skip_raw_or_byte_string(b, i),
            b'\'' => i = skip_char(b, i),
            _ if c.is_ascii_alphabetic() || c == b'_' => {
                while i < n && (b[i].is_ascii_alphanumeric() || b[i] == b'_') {
                    i += 1;
                }
            }
            _ if c.is_ascii_digit() => {
                let start = i;
                let radix = match b.get(i + 1) {
                    Some(b'x' | b'X') if c == b'0' => Some("hexadecimal"),
                    Some(b'b' | b'B') if c == b'0' => Some("binary"),
                    Some(b'o' | b'O') if c == b'0' => Some("octal"),
                    _ => None,
                };
                while i < n {
                    let d = b[i];
                    let exponent_sign = (d == b'+' || d == b'-')
                        && radix.is_none()
                        && matches!(b[i - 1], b'e' | b'E');
                    if d.is_ascii_alphanumeric() || d == b'_' || d == b'.' || exponent_sign {
                        i += 1;
                    } else {
                        break;
                    }
                }
                let token = &text[start..i];
                if let Some(radix) = radix {
                    return Some((
                        start,
                        format!(
                            "`{token}`: {radix} numbers are not accepted; write numbers in decimal"
                        ),
                    ));
                }
                if token.contains('_') {
                    return Some((
                        start,
                        format!("`{token}`: `_` separators are not accepted in numbers"),
                    ));
                }
            }
            _ => i += 1,
        }
    }
    None
}

/// The start of an identifier directly before the bracket at `open` (`Box(`, `Sphere (`), or
/// `open` itself.
fn name_before(text: &str, open: usize) -> usize {
    let before = &text[..open];
    let trimmed = before.trim_end_matches([' ', '\t']);
    let ident_start = trimmed
        .char_indices()
        .rev()
        .take_while(|&(_, c)| is_ident_char(c))
        .last()
        .map(|(i, _)| i);
    match ident_start {
        Some(s) if !trimmed[s..].starts_with(|c: char| c.is_ascii_digit()) => s,
        _ => open,
    }
}

/// Index just past the end of the block comment starting at `i` (ron's block comments nest).
fn skip_block_comment(b: &[u8], mut i: usize) -> usize {
    let mut depth = 0usize;
    while i < b.len() {
        if b[i] == b'/' && b.get(i + 1) == Some(&b'*') {
            depth += 1;
            i += 2;
        } else if b[i] == b'*' && b.get(i + 1) == Some(&b'/') {
            depth -= 1;
            i += 2;
            if depth == 0 {
                break;
            }
        } else {
            i += 1;
        }
    }
    i
}

/// Index just past the char literal starting at `i`: 'x' or '\n' or '\u{..}'.
fn skip_char(b: &[u8], mut i: usize) -> usize {
    i += 1;
    if b.get(i) == Some(&b'\\') {
        i += 2;
    }
    while i < b.len() && b[i] != b'\'' && b[i] != b'\n' {
        i += 1;
    }
    i + 1
}

/// Index just past the closing quote of a `"..."` string whose body starts at `i`.
fn skip_string(b: &[u8], mut i: usize) -> usize {
    while i < b.len() {
        match b[i] {
            b'\\' => i += 2,
            b'"' => return i + 1,
            _ => i += 1,
        }
    }
    b.len()
}

/// `r"`, `r#"`, `b"`, `br"`, `br#"` at `i`, not in the middle of an identifier.
fn starts_raw_or_byte_string(b: &[u8], i: usize) -> bool {
    if i > 0 && (b[i - 1].is_ascii_alphanumeric() || b[i - 1] == b'_') {
        return false;
    }
    let mut j = i;
    if b[j] == b'b' {
        j += 1;
        if b.get(j) == Some(&b'"') {
            return true;
        }
    }
    if b.get(j) != Some(&b'r') {
        return false;
    }
    j += 1;
    while b.get(j) == Some(&b'#') {
        j += 1;
    }
    b.get(j) == Some(&b'"')
}

fn skip_raw_or_byte_string(b: &[u8], mut i: usize) -> usize {
    if b[i] == b'b' {
        i += 1;
        if b[i] == b'"' {
            return skip_string(b, i + 1);
        }
    }
    // b[i] == b'r'
    i += 1;
    let mut hashes = 0;
    while b[i] == b'#' {
        hashes += 1;
        i += 1;
    }
    i += 1; // the opening quote
    while i < b.len() {
        if b[i] == b'"'
            && b[i + 1..]
                .iter()
                .take(hashes)
                .filter(|&&h| h == b'#')
                .count()
                == hashes
        {
            return i + 1 + hashes;
        }
        i += 1;
    }
    b.len()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn line_col_round_trip() {
        let t = "ab\ncdé\n\nx";
        for off in [0, 1, 3, 5, 7, 8, 9] {
            let (l, c) = line_col(t, off);
            assert_eq!(offset_of(t, l, c), off, "offset {off} -> {l}:{c}");
        }
        assert_eq!(line_col(t, 7), (2, 4)); // after 'é' (2 bytes)
    }

    #[test]
    fn value_start_cases() {
        let t = r#"(a: Box(min: (1, 2), s: "xy)z", /* ) */ r: (1, 2))"#;
        // closing paren of `(1, 2)` after min -> its opening paren
        let close = t.find("2)").unwrap() + 1;
        assert_eq!(value_start(t, close), t.find("(1, 2)").unwrap());
        // inside the string -> the opening quote
        let inside = t.find("xy").unwrap();
        assert_eq!(value_start(t, inside), inside - 1);
        // the Box's closing paren -> the name `Box`
        let box_close = t.len() - 1;
        assert_eq!(&t[box_close..=box_close], ")");
        assert_eq!(value_start(t, box_close), t.find("Box").unwrap());
        // a number stays put
        assert_eq!(value_start(t, 14), 14);
    }
}
