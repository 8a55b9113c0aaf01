//! Line-oriented tokenising shared by the text mesh readers.
//!
//! Lines keep their 1-based numbers so every parse error names `file:line`.
//! A comment character (TetGen's `#`) cuts a line; blank lines are skipped.

use std::path::{Path, PathBuf};
use std::str::FromStr;

use crate::error::Error;

/// One non-blank line split into whitespace-separated fields.
pub(crate) struct Record<'a> {
    pub line: usize,
    pub fields: Vec<&'a str>,
    path: &'a Path,
}

impl<'a> Record<'a> {
    /// A parse error at this record's line.
    pub fn error(&self, message: impl Into<String>) -> Error {
        Error::Parse {
            path: self.path.to_path_buf(),
            line: self.line,
            message: message.into(),
        }
    }

    /// Field `i` parsed as `T`; `what` names it in errors.
    pub fn get<T: FromStr>(&self, i: usize, what: &str) -> Result<T, Error> {
        let token = self.fields.get(i).ok_or_else(|| {
            self.error(format!(
                "missing {what} (field {} of {})",
                i + 1,
                self.fields.len()
            ))
        })?;
        token
            .parse()
            .map_err(|_| self.error(format!("{what}: cannot parse '{token}'")))
    }

    /// Field `i` as a finite float.
    pub fn float(&self, i: usize, what: &str) -> Result<f64, Error> {
        let v: f64 = self.get(i, what)?;
        if v.is_finite() {
            Ok(v)
        } else {
            Err(self.error(format!("{what} is not finite ({v})")))
        }
    }

    /// Requires at least `n` fields.
    pub fn expect_len(&self, n: usize, what: &str) -> Result<(), Error> {
        if self.fields.len() < n {
            Err(self.error(format!(
                "{what} needs {n} fields, found {}",
                self.fields.len()
            )))
        } else {
            Ok(())
        }
    }
}

/// Iterator over the non-blank, comment-stripped lines of a text.
pub(crate) struct Lines<'a> {
    path: &'a Path,
    inner: std::iter::Enumerate<std::str::Lines<'a>>,
    comment: Option<char>,
    last_line: usize,
    lines_in_file: usize,
}

impl<'a> Lines<'a> {
    pub fn new(path: &'a Path, text: &'a str, comment: Option<char>) -> Self {
        Lines {
            path,
            inner: text.lines().enumerate(),
            comment,
            last_line: 0,
            lines_in_file: text.lines().count(),
        }
    }

    /// Room to reserve for `n` records announced by a header: at most one
    /// per line of the file, so a header claiming 4e9 entries cannot make
    /// the reader allocate for them (the file then simply ends early, an
    /// error naming the line).
    pub fn capacity(&self, n: usize) -> usize {
        n.min(self.lines_in_file)
    }

    /// The next record, or an error saying the file ended while `what` was expected.
    pub fn next_record(&mut self, what: &str) -> Result<Record<'a>, Error> {
        self.next().ok_or_else(|| Error::Parse {
            path: self.path.to_path_buf(),
            line: self.last_line,
            message: format!("file ends early: expected {what}"),
        })
    }

    fn strip(&self, line: &'a str) -> &'a str {
        match self.comment.and_then(|c| line.find(c)) {
            Some(k) => &line[..k],
            None => line,
        }
    }
}

impl<'a> Iterator for Lines<'a> {
    type Item = Record<'a>;
    fn next(&mut self) -> Option<Record<'a>> {
        while let Some((i, line)) = self.inner.next() {
            self.last_line = i + 1;
            let fields: Vec<&str> = self.strip(line).split_whitespace().collect();
            if !fields.is_empty() {
                return Some(Record {
                    line: i + 1,
                    fields,
                    path: self.path,
                });
            }
        }
        None
    }
}

/// Reads a whole text file, naming it in the error.
pub(crate) fn read_text(path: &Path) -> Result<String, Error> {
    let bytes = super::read_input(path)?;
    String::from_utf8(bytes).map_err(|e| {
        let line = 1 + e.as_bytes()[..e.utf8_error().valid_up_to()]
            .iter()
            .filter(|&&b| b == b'\n')
            .count();
        Error::Parse {
            path: PathBuf::from(path),
            line,
            message: "not a text file (invalid UTF-8)".into(),
        }
    })
}
