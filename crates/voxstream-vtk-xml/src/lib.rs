//! # voxstream-vtk-xml: the data-array encodings of VTK's XML file formats
//!
//! VTK's XML formats (`.vti` ImageData, `.vtp` PolyData, `.vtu` UnstructuredGrid, …;
//! <https://docs.vtk.org/en/latest/design_documents/VTKFileFormats.html>) store each `DataArray` in one of three
//! ways: `ascii` (numbers as text, left to each reader: what they mean depends on the array's type), `binary` (the
//! bytes as base64 inside the element) or `appended` (at an `offset` into the `AppendedData` section after the XML,
//! `raw` bytes or `base64`). Binary and appended arrays open with a header of unsigned integers, `UInt32` or
//! `UInt64` as the `VTKFile`'s `header_type` says, in the file's `byte_order`: uncompressed, the array's byte count;
//! compressed (`compressor="vtkZLibDataCompressor"`), `[blocks, block size, last block size, compressed sizes…]`
//! followed by that many zlib blocks. Base64 data encodes the header and the bytes as one run or (compressed, or as
//! some writers do) two.
//!
//! This crate decodes that layer once, for the geometry crate's particle reader (`.vtp`, `.vtu`) and the store's
//! volume reader (`.vti`): [`Encoding`] from the `VTKFile` attributes, then [`decode_base64_array`] or
//! [`decode_raw_array`] to exactly the bytes the reader expects. Every size is checked (checked arithmetic
//! throughout) before anything is allocated or inflated: the block sizes must add up to the expected bytes, the
//! compressed bytes must be able to inflate to them within [`Bounds::deflate_max_ratio`], and each block must
//! inflate to exactly its announced size (zlib's adler32 checked). What the array's bytes mean (their type) is the
//! reader's.

mod arrays;
mod encoding;
mod scan;

pub use arrays::{decode_base64_array, decode_raw_array, ArrayError, Bounds};
pub use encoding::{Encoding, UnsupportedCompressor};
pub use scan::{appended_base64_text, attribute, find, xml_end};

/// The most deflate can expand (1032:1): a compressed array announcing more than this many times its compressed
/// bytes is refused before it is inflated.
pub const DEFLATE_MAX_RATIO: u64 = 1032;
