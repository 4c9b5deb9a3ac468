//! Source positions: [`Span`] (a byte range into the model text) and [`SourceFile`]
//! (the text plus a line table for 1-based `line:column` lookups).

use std::ops::Range;

/// A half-open byte range `start..end` into the model text (the `.hyb` file, or the text
/// that [`crate::tokens::restring`] builds from the macro's tokens).
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Hash, PartialOrd, Ord)]
pub struct Span {
    /// First byte of the range.
    pub start: usize,
    /// One past the last byte of the range.
    pub end: usize,
}

impl Span {
    /// The span `start..end` (the bounds are swapped if given in the wrong order).
    pub fn new(start: usize, end: usize) -> Span {
        if start <= end {
            Span { start, end }
        } else {
            Span {
                start: end,
                end: start,
            }
        }
    }

    /// An empty span at `pos`.
    pub fn point(pos: usize) -> Span {
        Span {
            start: pos,
            end: pos,
        }
    }

    /// The smallest span covering both `self` and `other`.
    pub fn to(self, other: Span) -> Span {
        Span {
            start: self.start.min(other.start),
            end: self.end.max(other.end),
        }
    }

    /// Length in bytes.
    pub fn len(self) -> usize {
        self.end - self.start
    }

    /// Whether the span covers no byte.
    pub fn is_empty(self) -> bool {
        self.start == self.end
    }

    /// The span as a `Range<usize>`.
    pub fn range(self) -> Range<usize> {
        self.start..self.end
    }
}

impl From<Range<usize>> for Span {
    fn from(r: Range<usize>) -> Span {
        Span::new(r.start, r.end)
    }
}

impl From<pest::Span<'_>> for Span {
    fn from(s: pest::Span<'_>) -> Span {
        Span::new(s.start(), s.end())
    }
}

/// A named source text with a table of line starts, for `line:column` lookups.
#[derive(Clone, Debug)]
pub struct SourceFile {
    /// The name shown in diagnostics (a path, or `<input>`).
    pub name: String,
    /// The full text.
    pub text: String,
    line_starts: Vec<usize>,
}

impl SourceFile {
    /// Wraps `text` under the display name `name`.
    pub fn new(name: impl Into<String>, text: impl Into<String>) -> SourceFile {
        let text = text.into();
        let line_starts = line_starts(&text);
        SourceFile {
            name: name.into(),
            text,
            line_starts,
        }
    }

    /// 1-based `(line, column)` of byte `offset`; see [`line_col`].
    pub fn line_col(&self, offset: usize) -> (usize, usize) {
        line_col_with(&self.text, &self.line_starts, offset)
    }

    /// The text of the 1-based line `line`, without its line terminator.
    pub fn line_text(&self, line: usize) -> &str {
        line_text_with(&self.text, &self.line_starts, line)
    }
}

/// Byte offsets at which each line of `text` starts (the first is always 0).
pub fn line_starts(text: &str) -> Vec<usize> {
    std::iter::once(0)
        .chain(text.match_indices('\n').map(|(i, _)| i + 1))
        .collect()
}

/// 1-based `(line, column)` of byte `offset` in `text`. The column counts characters
/// (not bytes) from the start of the line, as pest and rustc do. Offsets past the end
/// (or inside a multi-byte character) are clamped to a valid position.
pub fn line_col(text: &str, offset: usize) -> (usize, usize) {
    line_col_with(text, &line_starts(text), offset)
}

fn clamp_to_char_boundary(text: &str, mut offset: usize) -> usize {
    offset = offset.min(text.len());
    while !text.is_char_boundary(offset) {
        offset -= 1;
    }
    offset
}

fn line_col_with(text: &str, starts: &[usize], offset: usize) -> (usize, usize) {
    let offset = clamp_to_char_boundary(text, offset);
    // Index of the last line start <= offset.
    let line = starts.partition_point(|&s| s <= offset).max(1) - 1;
    let col = text[starts[line]..offset].chars().count() + 1;
    (line + 1, col)
}

fn line_text_with<'a>(text: &'a str, starts: &[usize], line: usize) -> &'a str {
    if line == 0 || line > starts.len() {
        return "";
    }
    let start = starts[line - 1];
    let end = starts.get(line).map_or(text.len(), |&e| e - 1);
    text[start..end].trim_end_matches('\r')
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn line_and_column_are_one_based() {
        let src = "ab\ncd\n\nxé y";
        assert_eq!(line_col(src, 0), (1, 1));
        assert_eq!(line_col(src, 1), (1, 2));
        assert_eq!(line_col(src, 2), (1, 3));
        assert_eq!(line_col(src, 3), (2, 1));
        assert_eq!(line_col(src, 6), (3, 1));
        assert_eq!(line_col(src, 7), (4, 1));
        // 'é' is two bytes but one column.
        assert_eq!(line_col(src, 10), (4, 3));
        assert_eq!(line_col(src, 11), (4, 4));
        // Past the end: clamped.
        assert_eq!(line_col(src, 100), (4, 5));
        // Inside a multi-byte character: clamped back to its start.
        assert_eq!(line_col(src, 9), (4, 2));
    }

    #[test]
    fn line_text_strips_terminators() {
        let f = SourceFile::new("m.hyb", "one\r\ntwo\nthree");
        assert_eq!(f.line_text(1), "one");
        assert_eq!(f.line_text(2), "two");
        assert_eq!(f.line_text(3), "three");
        assert_eq!(f.line_text(4), "");
        assert_eq!(f.line_text(0), "");
    }

    #[test]
    fn span_join_and_order() {
        let a = Span::new(5, 2);
        assert_eq!(a, Span { start: 2, end: 5 });
        assert_eq!(a.to(Span::new(7, 9)), Span::new(2, 9));
        assert_eq!(a.len(), 3);
        assert!(Span::point(4).is_empty());
    }
}
