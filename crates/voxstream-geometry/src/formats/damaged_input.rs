//! The mesh readers' shared fuzz-style test: every prefix and every one-byte change of a valid file parses without
//! a panic, and a prefix that cuts off what the file declares is an error, not a smaller mesh.
//!
//! Where truncation is detectable depends on the format: binary files whose header declares their counts (binary PLY
//! and STL) are an error at every shorter prefix; text files whose header declares counts (ASCII PLY, OFF) are an
//! error at every prefix that leaves a declared value out (a cut inside the last number leaves a shorter number, a
//! valid file); text files without counts (OBJ, ASCII STL between facets) can be cut into a valid smaller file, so
//! for them only "no panic" is asserted.

use crate::error::GeometryError;

/// Which prefixes of a valid file must be errors.
#[derive(Clone, Copy, Debug)]
pub(crate) enum Truncation {
    /// Every prefix shorter than the file.
    EveryPrefix,
    /// Every prefix of at least this many bytes, shorter than the file.
    From(usize),
    /// Every prefix of at most this many bytes (see [`last_value_start`]).
    Through(usize),
    /// None: a prefix may be a valid smaller file.
    Undetectable,
}

/// Where the last whitespace-separated value of a text file starts: a prefix of at most this many bytes leaves at
/// least one value out.
pub(crate) fn last_value_start(file: &[u8]) -> usize {
    let end = file.iter().rposition(|b| !b.is_ascii_whitespace()).map_or(0, |e| e + 1);
    file[..end].iter().rposition(u8::is_ascii_whitespace).map_or(0, |s| s + 1)
}

/// Parses `file` (which must be valid), each of its prefixes (asserting that those `truncation` covers are errors),
/// and `file` with each byte replaced by each of `replacements` (asserting only that nothing panics).
pub(crate) fn no_input_panics<T: std::fmt::Debug>(
    parse: impl Fn(&[u8]) -> Result<T, GeometryError>,
    file: &[u8],
    replacements: &[u8],
    truncation: Truncation,
) {
    if let Err(error) = parse(file) {
        panic!("the whole file is not read: {error}");
    }
    for cut in 0..file.len() {
        let result = parse(&file[..cut]);
        let must_fail = match truncation {
            Truncation::EveryPrefix => true,
            Truncation::From(first) => cut >= first,
            Truncation::Through(last) => cut <= last,
            Truncation::Undetectable => false,
        };
        if must_fail {
            assert!(result.is_err(), "the first {cut} of {} bytes are read as {result:?}", file.len());
        }
    }
    for at in 0..file.len() {
        for &byte in replacements {
            let mut changed = file.to_vec();
            changed[at] = byte;
            let _ = parse(&changed);
        }
    }
}

#[test]
fn the_last_value_starts_after_the_last_separator() {
    assert_eq!(last_value_start(b"3 0 1 2\n"), 6);
    assert_eq!(last_value_start(b"12  \n\n"), 0);
    assert_eq!(last_value_start(b""), 0);
}
