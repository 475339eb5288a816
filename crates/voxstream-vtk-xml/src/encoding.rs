//! How a VTK XML file encodes its binary arrays: the `VTKFile` element's `byte_order`, `header_type` and
//! `compressor`.

/// The `VTKFile` attributes that decoding binary and appended arrays needs.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct Encoding {
    /// `byte_order="BigEndian"` (the headers' and the values' byte order).
    pub big_endian: bool,
    /// `header_type="UInt64"` (otherwise `UInt32`).
    pub header_u64: bool,
    /// `compressor="vtkZLibDataCompressor"`: arrays are zlib blocks.
    pub compressed: bool,
}

/// A `compressor` other than zlib (LZ4, LZMA): not read. Holds the compressor's name.
#[derive(Clone, Debug, PartialEq, Eq, thiserror::Error)]
#[error("compressor {0}")]
pub struct UnsupportedCompressor(pub String);

impl Encoding {
    /// The encoding a `VTKFile` element's attributes give (`attr` looks one up by name).
    pub fn from_attributes(attr: impl Fn(&str) -> Option<String>) -> Result<Encoding, UnsupportedCompressor> {
        let compressed = match attr("compressor").as_deref() {
            None | Some("") => false,
            Some("vtkZLibDataCompressor") => true,
            Some(other) => return Err(UnsupportedCompressor(other.to_string())),
        };
        Ok(Encoding {
            big_endian: attr("byte_order").as_deref() == Some("BigEndian"),
            header_u64: attr("header_type").as_deref() == Some("UInt64"),
            compressed,
        })
    }

    /// Bytes of one header integer (4 or 8).
    pub fn header_size(self) -> usize {
        if self.header_u64 {
            8
        } else {
            4
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn attributes_give_the_encoding() {
        let file = |pairs: &'static [(&'static str, &'static str)]| {
            move |name: &str| pairs.iter().find(|(n, _)| *n == name).map(|(_, v)| v.to_string())
        };
        assert_eq!(Encoding::from_attributes(file(&[])), Ok(Encoding::default()));
        const ALL: [(&str, &str); 3] =
            [("byte_order", "BigEndian"), ("header_type", "UInt64"), ("compressor", "vtkZLibDataCompressor")];
        let encoding = Encoding::from_attributes(file(&ALL)).unwrap();
        assert_eq!(encoding, Encoding { big_endian: true, header_u64: true, compressed: true });
        assert_eq!(encoding.header_size(), 8);
        let lz4 = Encoding::from_attributes(file(&[("compressor", "vtkLZ4DataCompressor")]));
        assert_eq!(lz4.unwrap_err().to_string(), "compressor vtkLZ4DataCompressor");
    }
}
