//! Enums written as words: one table of `(variant, word)` pairs serves
//! both directions (the word of a variant, the variant of a word) and the
//! list of accepted words in messages.
#![warn(missing_docs)]

/// The word of `v` (every variant is in its table).
pub(crate) fn word_of<T: Copy + PartialEq>(table: &[(T, &'static str)], v: T) -> &'static str {
    table
        .iter()
        .find(|(t, _)| *t == v)
        .map(|(_, w)| *w)
        .expect("every variant has a word in its table")
}

/// The variant whose word is `s`.
pub(crate) fn from_word<T: Copy>(table: &[(T, &'static str)], s: &str) -> Option<T> {
    table.iter().find(|(_, w)| *w == s).map(|(t, _)| *t)
}

/// The words, quoted, for a message: `'a', 'b' or 'c'`.
pub(crate) fn quoted_choices<T>(table: &[(T, &'static str)]) -> String {
    let mut out = String::new();
    for (i, (_, w)) in table.iter().enumerate() {
        if i > 0 {
            out.push_str(if i + 1 == table.len() { " or " } else { ", " });
        }
        out.push('\'');
        out.push_str(w);
        out.push('\'');
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn both_directions_and_the_list() {
        const T: [(u8, &str); 3] = [(1, "a"), (2, "b"), (3, "c")];
        assert_eq!(word_of(&T, 2), "b");
        assert_eq!(from_word(&T, "c"), Some(3));
        assert_eq!(from_word(&T, "d"), None);
        assert_eq!(quoted_choices(&T), "'a', 'b' or 'c'");
        assert_eq!(quoted_choices(&T[..2]), "'a' or 'b'");
    }
}
