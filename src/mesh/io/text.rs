//! Tokenising shared by the mesh readers.
//!
//! [`Lines`] splits line-oriented text (TetGen): lines keep their 1-based
//! numbers so every parse error names `file:line`; a comment character
//! (TetGen's `#`) cuts a line; blank lines are skipped. [`Cursor`] walks
//! files that mix text and binary data (Gmsh, legacy VTK): errors name the
//! line in text and the byte offset in binary data.

use std::path::{Path, PathBuf};
use std::str::FromStr;

use crate::error::{Error, Result};

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

/// A place in a file: its line, or in binary data its byte.
pub(crate) struct Site {
    path: PathBuf,
    line: usize,
    byte: Option<usize>,
}

impl Site {
    /// Where it is, in words: `line 12`, or `byte 4013` in binary data.
    pub fn place(&self) -> String {
        match self.byte {
            Some(b) => format!("byte {b}"),
            None => format!("line {}", self.line),
        }
    }

    /// A parse error here.
    pub fn error(&self, message: impl Into<String>) -> Error {
        let message = message.into();
        Error::Parse {
            path: self.path.clone(),
            line: self.line,
            message: match self.byte {
                Some(b) => format!("byte {b}: {message}"),
                None => message,
            },
        }
    }
}

/// How a binary part of a file is laid out.
#[derive(Clone, Copy)]
pub(crate) struct Binary {
    pub big_endian: bool,
}

/// A read position in a file's bytes: text tokens, or binary numbers
/// while `binary` is set (a Gmsh file after `$MeshFormat` said it is
/// binary; a legacy VTK data block in a `BINARY` file).
pub(crate) struct Cursor<'a> {
    pub path: &'a Path,
    pub data: &'a [u8],
    pub pos: usize,
    /// Set while reading binary data: numbers are bytes, errors name
    /// byte offsets instead of lines.
    pub binary: Option<Binary>,
}

impl<'a> Cursor<'a> {
    pub fn line_at(&self, pos: usize) -> usize {
        1 + self.data[..pos.min(self.data.len())]
            .iter()
            .filter(|&&b| b == b'\n')
            .count()
    }

    /// An error at byte `pos`: by line in text files, by byte offset in
    /// binary ones (past the format line, lines mean nothing there).
    pub fn error_at(&self, pos: usize, message: impl Into<String>) -> Error {
        self.site(pos).error(message)
    }

    /// Where byte `pos` is, as [`Cursor::error_at`] names it: kept by
    /// code that builds its errors while the cursor moves on.
    pub fn site(&self, pos: usize) -> Site {
        Site {
            path: self.path.to_path_buf(),
            line: if self.binary.is_some() {
                0
            } else {
                self.line_at(pos)
            },
            byte: self.binary.is_some().then_some(pos),
        }
    }

    pub fn binary_error(&self, pos: usize, message: impl Into<String>) -> Error {
        Site {
            path: self.path.to_path_buf(),
            line: 0,
            byte: Some(pos),
        }
        .error(message)
    }

    pub fn ends_early(&self, what: &str) -> Error {
        self.error_at(self.data.len(), format!("file ends early: expected {what}"))
    }

    /// Room to reserve for `n` announced entries: at most one per two bytes
    /// left, so a header claiming 4e9 entries cannot make the reader
    /// allocate for them.
    pub fn capacity(&self, n: u64) -> usize {
        let left = (self.data.len() - self.pos) / 2;
        usize::try_from(n).unwrap_or(usize::MAX).min(left)
    }

    /// The offset of the next item: in text, past the whitespace before
    /// it, so that errors name the line where it stands.
    pub fn mark(&mut self) -> usize {
        if self.binary.is_none() {
            while self.pos < self.data.len() && self.data[self.pos].is_ascii_whitespace() {
                self.pos += 1;
            }
        }
        self.pos
    }

    /// The next whitespace-separated text token and its offset.
    pub fn token_opt(&mut self) -> Result<Option<(usize, &'a str)>> {
        while self.pos < self.data.len() && self.data[self.pos].is_ascii_whitespace() {
            self.pos += 1;
        }
        let start = self.pos;
        if start == self.data.len() {
            return Ok(None);
        }
        while self.pos < self.data.len() && !self.data[self.pos].is_ascii_whitespace() {
            self.pos += 1;
        }
        std::str::from_utf8(&self.data[start..self.pos])
            .map(|t| Some((start, t)))
            .map_err(|_| Error::Parse {
                path: self.path.to_path_buf(),
                line: self.line_at(start),
                message: "not a text file (invalid UTF-8)".into(),
            })
    }

    pub fn token(&mut self, what: &str) -> Result<(usize, &'a str)> {
        self.token_opt()?.ok_or_else(|| self.ends_early(what))
    }

    /// A text token parsed as `T`.
    pub fn parse<T: FromStr>(&mut self, what: &str) -> Result<T> {
        let (at, token) = self.token(what)?;
        token
            .parse()
            .map_err(|_| self.error_at(at, format!("{what}: cannot parse '{token}'")))
    }

    /// The rest of the current line (for quoted names).
    pub fn rest_of_line(&mut self) -> (usize, &'a str) {
        let start = self.pos;
        while self.pos < self.data.len() && self.data[self.pos] != b'\n' {
            self.pos += 1;
        }
        (
            start,
            std::str::from_utf8(&self.data[start..self.pos]).unwrap_or(""),
        )
    }

    /// Skips to just past the end of the current line: binary data starts
    /// on the byte after a header line's newline.
    pub fn end_of_line(&mut self) {
        self.rest_of_line();
        self.pos = (self.pos + 1).min(self.data.len());
    }

    /// In a binary file, moves past the section header's newline.
    pub fn start_binary_block(&mut self) {
        if self.binary.is_some() {
            self.end_of_line();
        }
    }

    pub fn bytes<const N: usize>(&mut self, what: &str) -> Result<[u8; N]> {
        let end = self.pos + N;
        let Some(b) = self.data.get(self.pos..end) else {
            return Err(self.ends_early(what));
        };
        self.pos = end;
        Ok(b.try_into().expect("slice of N bytes"))
    }

    pub fn big_endian(&self) -> bool {
        self.binary.is_some_and(|b| b.big_endian)
    }
}
