//! Whitespace-separated numeric tables (`#` comments), with errors that name the file
//! and the line.

use std::fmt;
use std::path::{Path, PathBuf};

/// A dataset file could not be read or has a bad line.
#[derive(Debug, thiserror::Error)]
pub enum ReadError {
    /// The file could not be opened or read.
    #[error("{}: {source}", .path.display())]
    Io {
        /// The file.
        path: PathBuf,
        /// The I/O error.
        source: std::io::Error,
    },
    /// A line is malformed (truncated, not a number, not finite, wrong value).
    #[error("{}:{line}: {problem}", .path.display())]
    BadLine {
        /// The file.
        path: PathBuf,
        /// 1-based line number.
        line: usize,
        /// What is wrong.
        problem: LineProblem,
    },
}

/// What is wrong with a line.
#[derive(Debug, Clone, PartialEq)]
pub enum LineProblem {
    /// Fewer fields than the format has (a truncated line).
    Truncated {
        /// Fields expected.
        expected: usize,
        /// Fields found.
        found: usize,
    },
    /// More fields than the format has.
    TooManyFields {
        /// Fields expected.
        expected: usize,
        /// Fields found.
        found: usize,
    },
    /// A field is not a number.
    NotANumber {
        /// 1-based column.
        column: usize,
        /// The text found.
        text: String,
    },
    /// A field is NaN or infinite.
    NotFinite {
        /// 1-based column.
        column: usize,
    },
    /// A value is out of its domain (explained).
    Invalid(String),
}

impl fmt::Display for LineProblem {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            Self::Truncated { expected, found } => {
                write!(f, "truncated line: {found} of {expected} fields")
            }
            Self::TooManyFields { expected, found } => {
                write!(f, "{found} fields where {expected} were expected")
            }
            Self::NotANumber { column, text } => {
                write!(f, "field {column} is not a number: `{text}`")
            }
            Self::NotFinite { column } => write!(f, "field {column} is not finite"),
            Self::Invalid(why) => f.write_str(why),
        }
    }
}

/// One data line of a table: its 1-based line number and its values.
#[derive(Debug, Clone, PartialEq)]
pub struct Row<const C: usize> {
    /// 1-based line number in the file.
    pub line: usize,
    /// The values.
    pub values: [f64; C],
}

/// Reads a table of `C` numeric columns; skips blank lines and lines starting with `#`.
pub fn read_table<const C: usize>(path: &Path) -> Result<Vec<Row<C>>, ReadError> {
    let text = std::fs::read_to_string(path).map_err(|source| ReadError::Io {
        path: path.to_owned(),
        source,
    })?;
    parse_table(path, &text)
}

/// Parses the text of a table (see [`read_table`]).
pub fn parse_table<const C: usize>(path: &Path, text: &str) -> Result<Vec<Row<C>>, ReadError> {
    let mut rows = Vec::with_capacity(text.len() / 32);
    visit_table(path, text, |row| rows.push(row))?;
    Ok(rows)
}

/// Reads a table of `C` numeric columns and hands each row to `visit` (no row vector).
pub fn read_table_with<const C: usize>(
    path: &Path,
    visit: impl FnMut(Row<C>),
) -> Result<(), ReadError> {
    let text = std::fs::read_to_string(path).map_err(|source| ReadError::Io {
        path: path.to_owned(),
        source,
    })?;
    visit_table(path, &text, visit)
}

/// Parses the text of a table, handing each row to `visit`.
///
/// Plain lines (ASCII decimals such as `-12.345` separated by spaces or tabs) take a fast
/// path: the digits are gathered into an integer and divided by a power of ten, which
/// is exact rounding when both are exactly representable (at most 2⁵³ and 10²²), so the
/// values are those `str::parse` gives. Any other line (exponents, long mantissas,
/// comments, errors) goes through the general parser.
pub fn visit_table<const C: usize>(
    path: &Path,
    text: &str,
    mut visit: impl FnMut(Row<C>),
) -> Result<(), ReadError> {
    let bytes = text.as_bytes();
    let mut start = 0;
    let mut line = 0;
    while start < bytes.len() {
        line += 1;
        let (fast, end) = plain_line::<C>(bytes, start);
        match fast {
            Plain::Row(values) => visit(Row { line, values }),
            Plain::Blank => {}
            Plain::Other => {
                let raw = text.get(start..end).unwrap_or_default();
                if let Some(row) = general_line(path, line, raw.trim_end_matches('\r'))? {
                    visit(row);
                }
            }
        }
        start = end + 1;
    }
    Ok(())
}

/// What the fast path made of a line.
enum Plain<const C: usize> {
    /// `C` plain decimals.
    Row([f64; C]),
    /// Only spaces and tabs.
    Blank,
    /// Anything else: for the general parser.
    Other,
}

/// `10^k`, exact in `f64` for `k ≤ 22`.
const POWERS_OF_TEN: [f64; 23] = [
    1e0, 1e1, 1e2, 1e3, 1e4, 1e5, 1e6, 1e7, 1e8, 1e9, 1e10, 1e11, 1e12, 1e13, 1e14, 1e15, 1e16,
    1e17, 1e18, 1e19, 1e20, 1e21, 1e22,
];

/// The line starting at `start` through the fast path, and where it ends (the index of
/// its `\n`, or the text's length).
fn plain_line<const C: usize>(bytes: &[u8], start: usize) -> (Plain<C>, usize) {
    let mut values = [0.0; C];
    let mut found = 0;
    let mut i = start;
    let mut plain = true;
    loop {
        // Separators.
        while let Some(b' ' | b'\t' | b'\r') = bytes.get(i) {
            i += 1;
        }
        match bytes.get(i) {
            None | Some(b'\n') => break,
            Some(_) if found == C => plain = false,
            Some(_) => match plain_number(bytes, &mut i) {
                Some(v) => {
                    if let Some(slot) = values.get_mut(found) {
                        *slot = v;
                    }
                    found += 1;
                    continue;
                }
                None => plain = false,
            },
        }
        // Not plain: find the end of the line.
        while let Some(&b) = bytes.get(i) {
            if b == b'\n' {
                break;
            }
            i += 1;
        }
        break;
    }
    let result = match (plain, found) {
        (true, 0) => Plain::Blank,
        (true, n) if n == C => Plain::Row(values),
        _ => Plain::Other,
    };
    (result, i)
}

/// A plain decimal (`-`, digits, optionally `.` and digits) at `*i`, followed by a
/// separator or the end of the line; advances `*i` past it. `None` for anything else.
fn plain_number(bytes: &[u8], i: &mut usize) -> Option<f64> {
    let negative = bytes.get(*i) == Some(&b'-');
    let first = *i + usize::from(negative);
    let mut j = first;
    let mut mantissa: u64 = 0;
    let mut point = None;
    while let Some(&b) = bytes.get(j) {
        let d = b.wrapping_sub(b'0');
        if d < 10 {
            // Wraps only past 19 digits, which are refused below.
            mantissa = mantissa.wrapping_mul(10).wrapping_add(u64::from(d));
        } else if b == b'.' && point.is_none() {
            point = Some(j);
        } else {
            break;
        }
        j += 1;
    }
    if !matches!(bytes.get(j), None | Some(b' ' | b'\t' | b'\r' | b'\n')) {
        return None;
    }
    let (before, decimals) = match point {
        Some(p) => (p - first, j - p - 1),
        None => (j - first, 0),
    };
    let refused = before == 0 || (point.is_some() && decimals == 0) || before + decimals > 19;
    if refused || mantissa > 1 << 53 {
        return None;
    }
    let power = POWERS_OF_TEN.get(decimals)?;
    *i = j;
    // Both operands exact: the quotient is the correctly rounded value.
    let v = mantissa as f64 / power;
    Some(if negative { -v } else { v })
}

/// One line through the general parser: `None` for blank and comment lines.
fn general_line<const C: usize>(
    path: &Path,
    line: usize,
    raw: &str,
) -> Result<Option<Row<C>>, ReadError> {
    let trimmed = raw.trim();
    if trimmed.is_empty() || trimmed.starts_with('#') {
        return Ok(None);
    }
    let bad = |problem| ReadError::BadLine {
        path: path.to_owned(),
        line,
        problem,
    };
    let mut values = [0.0; C];
    let mut found = 0;
    for (column, field) in trimmed.split_ascii_whitespace().enumerate() {
        if column >= C {
            found = trimmed.split_ascii_whitespace().count();
            return Err(bad(LineProblem::TooManyFields { expected: C, found }));
        }
        let v: f64 = fast_float2::parse(field).map_err(|_| {
            bad(LineProblem::NotANumber {
                column: column + 1,
                text: field.to_owned(),
            })
        })?;
        if !v.is_finite() {
            return Err(bad(LineProblem::NotFinite { column: column + 1 }));
        }
        if let Some(slot) = values.get_mut(column) {
            *slot = v;
        }
        found += 1;
    }
    if found < C {
        return Err(bad(LineProblem::Truncated { expected: C, found }));
    }
    Ok(Some(Row { line, values }))
}

/// An error for line `line` of `path`.
pub fn invalid(path: &Path, line: usize, why: impl Into<String>) -> ReadError {
    ReadError::BadLine {
        path: path.to_owned(),
        line,
        problem: LineProblem::Invalid(why.into()),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn reports_line_numbers() {
        let p = Path::new("x.dat");
        let ok = "# h\n1 2 3\n\n4 5 6\n";
        let rows = parse_table::<3>(p, ok).unwrap();
        assert_eq!(rows.len(), 2);
        assert_eq!(rows[1].line, 4);
        assert_eq!(rows[1].values, [4.0, 5.0, 6.0]);
        let e = parse_table::<3>(p, "# h\n1 2 3\n4 5\n").unwrap_err();
        assert_eq!(e.to_string(), "x.dat:3: truncated line: 2 of 3 fields");
        let e = parse_table::<3>(p, "1 2 x3\n").unwrap_err();
        assert_eq!(e.to_string(), "x.dat:1: field 3 is not a number: `x3`");
        let e = parse_table::<3>(p, "1 nan 3\n").unwrap_err();
        assert_eq!(e.to_string(), "x.dat:1: field 2 is not finite");
        let e = parse_table::<2>(p, "1 2\n1 2 3\n").unwrap_err();
        assert_eq!(e.to_string(), "x.dat:2: 3 fields where 2 were expected");
        let e = parse_table::<2>(p, "1 2\n\n 3\t-\r\n").unwrap_err();
        assert_eq!(e.to_string(), "x.dat:3: field 2 is not a number: `-`");
    }

    /// Every field, plain or not, gets exactly the value `str::parse` gives.
    #[test]
    fn values_are_those_of_str_parse() {
        let mut fields: Vec<String> = [
            "0",
            "-0",
            "0.1",
            "-0.000",
            "1248444187.156",
            "1248444175.103",
            "3.787",
            "-0.257",
            "9007199254740992",
            "9007199254740993",
            "1.5e3",
            "-2E-2",
            "12.",
            ".5",
            "0.1234567890123456789",
            "123456789012345678901234",
            "0.0000000000000000000001",
            "0.00000000000000000000001",
            "+4.25",
            "1.41277290",
            "-3.89107760",
        ]
        .iter()
        .map(|f| f.to_string())
        .collect();
        let mut x = 0.000_123_456_789_f64;
        for k in 0..200 {
            fields.push(format!("{:.*}", k % 12, x));
            fields.push(format!("-{:.*}", (k + 5) % 17, x * 7.3));
            x *= 1.37;
        }
        let mut text = String::from("# header\r\n\n");
        for pair in fields.chunks(2) {
            let second = pair.get(1).map_or("1", String::as_str);
            text.push_str(&format!("  {}\t {} \r\n", pair[0], second));
        }
        let rows = parse_table::<2>(Path::new("x.dat"), &text).unwrap();
        assert_eq!(rows.len(), fields.len().div_ceil(2));
        for (row, pair) in rows.iter().zip(fields.chunks(2)) {
            let expected: f64 = pair[0].parse().unwrap();
            assert_eq!(row.values[0].to_bits(), expected.to_bits(), "{}", pair[0]);
            if let Some(second) = pair.get(1) {
                let expected: f64 = second.parse().unwrap();
                assert_eq!(row.values[1].to_bits(), expected.to_bits(), "{second}");
            }
        }
        assert_eq!(rows[0].line, 3);
    }
}
