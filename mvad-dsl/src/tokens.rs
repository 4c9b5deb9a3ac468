//! `hybrid!`'s input tokens -> model text for pest, plus a [`SourceMap`] that sends any
//! byte range of that text back to the tokens it came from, so that errors point at the
//! user's tokens.
//!
//! The text is the tokens' own spelling separated by one space (a line break where the
//! user's next token starts a new line), except after a
//! [`Spacing::Joint`] punct (so `<=` and `->` stay whole); group delimiters are spelled,
//! except [`Delimiter::None`] (from `macro_rules!` captures) which adds no text. Doc
//! comments (`///`, which reach a macro as `#[doc = ".."]`) are skipped like comments.

use std::ops::Range;

use proc_macro2::{Delimiter, Spacing, Span, TokenStream, TokenTree};

use crate::span;

/// For each token of the text, its byte range there and its span in the user's code,
/// sorted by range start (ranges do not overlap).
#[derive(Clone, Debug, Default)]
pub struct SourceMap {
    entries: Vec<(Range<usize>, Span)>,
}

impl SourceMap {
    /// Number of tokens mapped.
    pub fn len(&self) -> usize {
        self.entries.len()
    }

    /// Whether no token was mapped (empty input).
    pub fn is_empty(&self) -> bool {
        self.entries.is_empty()
    }

    /// The spans of the first and last tokens covering `range` of the text: the first
    /// token ending after `range.start` and the last token starting before `range.end`
    /// (the first one again for an empty range). Past the end of the text: the last token.
    /// `None` only if there are no tokens at all.
    pub fn lookup(&self, range: span::Span) -> Option<(Span, Span)> {
        let e = &self.entries;
        if e.is_empty() {
            return None;
        }
        let first = e.partition_point(|(r, _)| r.end <= range.start);
        if first >= e.len() {
            let last = e[e.len() - 1].1;
            return Some((last, last));
        }
        let last = e
            .partition_point(|(r, _)| r.start < range.end)
            .saturating_sub(1)
            .max(first);
        Some((e[first].1, e[last].1))
    }
}

/// One level of the depth-first walk: the tokens left and, for a spelled group, its
/// closing delimiter with its span.
type Level = (std::vec::IntoIter<TokenTree>, Option<(char, Span)>);

/// Spells `input` as model text and records where each token went (see the module docs).
///
/// Walks the token tree depth first with an explicit stack, so arbitrarily deep input
/// cannot overflow the stack here.
pub fn restring(input: TokenStream) -> (String, SourceMap) {
    let mut text = String::new();
    let mut entries = Vec::new();
    // Whether the next token must be preceded by a space.
    let mut space = false;
    // Each level: its remaining tokens and, for a spelled group, its closing delimiter.
    let mut stack: Vec<Level> = vec![(input.into_iter().collect::<Vec<_>>().into_iter(), None)];
    // Line of the previous token: a token on a later line is preceded by a line break
    // instead of a space, so that the text keeps the user's line structure (which the
    // "missing `;`" hint relies on). Spans without location information report line 0
    // or 1 throughout and keep the text on one line.
    let mut last_line = 0;
    let mut push = |text: &mut String, space: &mut bool, s: &str, span: Span, joint: bool| {
        let line = span.start().line;
        if *space {
            text.push(if line > last_line && !text.is_empty() {
                '\n'
            } else {
                ' '
            });
        }
        last_line = last_line.max(line);
        let start = text.len();
        text.push_str(s);
        entries.push((start..text.len(), span));
        *space = !joint;
    };
    while let Some((iter, _)) = stack.last_mut() {
        let Some(tt) = iter.next() else {
            if let Some((_, Some((close, span)))) = stack.pop() {
                push(&mut text, &mut space, &close.to_string(), span, false);
            }
            continue;
        };
        match tt {
            TokenTree::Ident(id) => {
                push(&mut text, &mut space, &id.to_string(), id.span(), false);
            }
            TokenTree::Literal(lit) => {
                push(&mut text, &mut space, &lit.to_string(), lit.span(), false);
            }
            TokenTree::Punct(p) => {
                if p.as_char() == '#' && skip_doc_attribute(iter) {
                    continue;
                }
                let joint = p.spacing() == Spacing::Joint;
                push(
                    &mut text,
                    &mut space,
                    &p.as_char().to_string(),
                    p.span(),
                    joint,
                );
            }
            TokenTree::Group(g) => {
                let delims = match g.delimiter() {
                    Delimiter::Parenthesis => Some(('(', ')')),
                    Delimiter::Brace => Some(('{', '}')),
                    Delimiter::Bracket => Some(('[', ']')),
                    Delimiter::None => None,
                };
                let inner = g.stream().into_iter().collect::<Vec<_>>().into_iter();
                match delims {
                    Some((open, close)) => {
                        push(
                            &mut text,
                            &mut space,
                            &open.to_string(),
                            g.span_open(),
                            false,
                        );
                        stack.push((inner, Some((close, g.span_close()))));
                    }
                    None => stack.push((inner, None)),
                }
            }
        }
    }
    (text, SourceMap { entries })
}

/// After a `#`: if the next tokens are `[doc = ..]` or `![doc = ..]` (a doc comment),
/// consumes them and returns true; otherwise consumes nothing.
fn skip_doc_attribute(iter: &mut std::vec::IntoIter<TokenTree>) -> bool {
    let rest = iter.as_slice();
    let is_doc = |t: &TokenTree| match t {
        TokenTree::Group(g) if g.delimiter() == Delimiter::Bracket => matches!(
            g.stream().into_iter().next(),
            Some(TokenTree::Ident(i)) if i == "doc"
        ),
        _ => false,
    };
    match rest {
        [TokenTree::Punct(bang), g, ..] if bang.as_char() == '!' && is_doc(g) => {
            iter.next();
            iter.next();
            true
        }
        [g, ..] if is_doc(g) => {
            iter.next();
            true
        }
        _ => false,
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use std::str::FromStr;

    fn text_of(src: &str) -> String {
        restring(TokenStream::from_str(src).expect("lexes")).0
    }

    #[test]
    fn spacing_rules() {
        assert_eq!(text_of("a<=b"), "a <= b");
        assert_eq!(text_of("x -> m"), "x -> m");
        assert_eq!(text_of("der(h) = -g;"), "der ( h ) = - g ;");
        assert_eq!(text_of("1e-3 + 2.0"), "1e-3 + 2.0");
        assert_eq!(text_of("{ a [b] }"), "{ a [ b ] }");
        assert_eq!(text_of("/// doc\nmodel M {}"), "model M { }");
        assert_eq!(text_of("#![doc = \"x\"] a # b"), "a # b");
        assert_eq!(text_of("a = 1\n  b = 2;\n\n c"), "a = 1\nb = 2 ;\nc");
    }

    #[test]
    fn lookup_maps_ranges_to_tokens() {
        let ts = TokenStream::from_str("model M { state h = (g + bad); }").unwrap();
        let (text, map) = restring(ts);
        assert_eq!(text, "model M { state h = ( g + bad ) ; }");
        let pos = |s: &str| text.find(s).unwrap();
        let line_col = |sp: Span| (sp.start().line, sp.start().column);
        // `bad` alone.
        let (a, b) = map
            .lookup(span::Span::new(pos("bad"), pos("bad") + 3))
            .unwrap();
        assert_eq!(line_col(a), (1, 25));
        assert_eq!(line_col(b), (1, 25));
        // `(g + bad)`: from `(` to `)`.
        let (a, b) = map.lookup(span::Span::new(pos("("), pos(")") + 1)).unwrap();
        assert_eq!(line_col(a), (1, 20));
        assert_eq!(line_col(b), (1, 28));
        // An empty range at a space maps to the next token.
        let (a, _) = map.lookup(span::Span::point(pos("bad") - 1)).unwrap();
        assert_eq!(line_col(a), (1, 25));
        // End of input: the last token.
        let (a, b) = map.lookup(span::Span::point(text.len())).unwrap();
        assert_eq!(line_col(a), (1, 31));
        assert_eq!(line_col(b), (1, 31));
        assert!(SourceMap::default().lookup(span::Span::point(0)).is_none());
    }

    #[test]
    fn deep_groups_do_not_overflow() {
        let n = 50_000;
        let mut ts = TokenStream::from_str("x").unwrap();
        for _ in 0..n {
            let g = proc_macro2::Group::new(Delimiter::Parenthesis, ts);
            ts = TokenStream::from(TokenTree::Group(g));
        }
        let (text, map) = restring(ts);
        assert_eq!(map.len(), 2 * n + 1);
        assert_eq!(text.len(), 2 * n + 1 + 2 * n);
    }
}
