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
pub fn visit_table<const C: usize>(
    path: &Path,
    text: &str,
    mut visit: impl FnMut(Row<C>),
) -> Result<(), ReadError> {
    for (i, raw) in text.lines().enumerate() {
        let line = i + 1;
        let trimmed = raw.trim();
        if trimmed.is_empty() || trimmed.starts_with('#') {
            continue;
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
            values[column] = v;
            found += 1;
        }
        if found < C {
            return Err(bad(LineProblem::Truncated { expected: C, found }));
        }
        visit(Row { line, values });
    }
    Ok(())
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
    }
}
