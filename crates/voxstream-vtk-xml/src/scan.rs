//! Finding things in a VTK XML file's bytes: the XML part before the appended data, an element's attributes, and
//! the appended base64 text.

use quick_xml::events::BytesStart;

/// Where `needle` first occurs in `haystack`.
pub fn find(haystack: &[u8], needle: &[u8]) -> Option<usize> {
    haystack.windows(needle.len()).position(|w| w == needle)
}

/// Where the `AppendedData` tag starts (if there is one), and where the XML part ends: after that tag's `>`, where
/// appended raw data (not XML) begins, or at the end of the file.
pub fn xml_end(bytes: &[u8]) -> (Option<usize>, usize) {
    let appended_at = find(bytes, b"<AppendedData");
    let end = appended_at.and_then(|a| find(bytes.get(a..)?, b">").map(|p| a + p + 1)).unwrap_or(bytes.len());
    (appended_at, end)
}

/// The attribute `name` of element `e`, as text (lossily decoded, not unescaped).
pub fn attribute(e: &BytesStart, name: &str) -> Option<String> {
    e.attributes()
        .flatten()
        .find(|a| a.key.as_ref() == name.as_bytes())
        .map(|a| String::from_utf8_lossy(&a.value).into_owned())
}

/// Appended base64 data: the characters after the `_` marker up to the closing tag, whitespace left out.
pub fn appended_base64_text(body: &[u8]) -> Vec<u8> {
    body.iter().copied().take_while(|&c| c != b'<').filter(|c| !c.is_ascii_whitespace()).collect()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_xml_part_ends_after_the_appended_data_tag() {
        let file = b"<VTKFile><AppendedData encoding=\"raw\">_\x00\x01</AppendedData></VTKFile>";
        let (at, end) = xml_end(file);
        assert_eq!(at, Some(9));
        assert_eq!(&file[end..end + 1], b"_");
        assert_eq!(xml_end(b"<VTKFile/>"), (None, 10));
        assert_eq!(appended_base64_text(b"QUJD\n  REVG </AppendedData>"), b"QUJDREVG");
        assert_eq!(find(b"abc", b"c"), Some(2));
        assert_eq!(find(b"abc", b"d"), None);
    }
}
