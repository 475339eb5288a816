//! Words of text formats as the readers use them: parsed as UTF-8, and shown in error messages cut short.

/// Most characters of a word an error message shows.
pub const SHOWN_CHARS: usize = 40;

/// A word as text for parsing (words that are not UTF-8 parse as nothing).
pub fn text(word: &[u8]) -> &str {
    std::str::from_utf8(word).unwrap_or("\u{fffd}")
}

/// `text` for an error message, cut to [`SHOWN_CHARS`].
pub fn shown(text: &str) -> String {
    let mut chars = text.chars();
    let mut out: String = chars.by_ref().take(SHOWN_CHARS).collect();
    if chars.next().is_some() {
        out.push('…');
    }
    out
}

/// A word of bytes for an error message (not UTF-8 shown lossily), cut to [`SHOWN_CHARS`].
pub fn shown_bytes(word: &[u8]) -> String {
    shown(&String::from_utf8_lossy(word))
}
