//! zarrs's codecs with strict decoding: `zstd` and `gzip` that stop at the chunk's known size, `blosc` that refuses a
//! chunk whose header declares more than that size, and `crc32c` that verifies its checksum on every read.
//!
//! zarrs's own zstd decoder allocates whatever the frame header declares (or inflates without end when it declares
//! nothing), and its gzip decoder inflates without end: one brick of a 77 KB shard could inflate to 1 GiB. Every
//! chunk's decoded size is known before decoding (a brick is `brick_size³ ×` sample size; zarrs passes it as the
//! decoded representation), so the output is bounded by it: fixed-size chunks decode into exactly that many bytes,
//! and anything more is an error naming the bound. Chunks of unknown size are bounded by [`UNKNOWN_SIZE_BOUND`].
//!
//! zarrs's blosc decoder allocates the size a chunk's 16-byte header declares (up to 2 GiB) and decompresses into it:
//! a blosc chunk of a few hundred kilobytes can fill it. c-blosc never writes past the declared size, so checking the
//! header against the bound before zarrs decodes bounds the output (the header's layout is c-blosc's documented
//! format: version, compressor version, flags, type size, then `nbytes`, `blocksize` and `cbytes` as little-endian
//! `u32`s).
//!
//! zarrs's `crc32c` verifies the checksum when it decodes a whole chunk, but its partial decoder (the one a shard's
//! bricks are read through) only strips the four bytes: a flipped bit in a brick went unnoticed. Here a brick is
//! always decoded whole (it is read whole anyway), so its checksum is always verified.
//!
//! zarrs builds a Zarr v2 array's blosc compressor itself rather than through the registry; [`with_strict_blosc`]
//! re-creates such an array from its metadata converted to v3 (zarrs's own conversion), whose codecs come from the
//! registry.
//!
//! [`register`] also installs voxstream's own `voxstream.wavelet` ([`crate::wavelet_codec`]).
//!
//! [`register`] installs the codecs into zarrs's runtime registry, which takes precedence over zarrs's built-in
//! codecs of the same names, for Zarr v3 and v2 alike; encoding is zarrs's own, unchanged.

use std::borrow::Cow;
use std::io::Read;
use std::sync::{Arc, Once};

use zarrs::array::codec::api::{
    BytesToBytesCodecTraits, Codec, CodecError, CodecMetadataOptions, CodecOptions, CodecTraits, CodecTraitsV2,
    CodecTraitsV3, PartialDecoderCapability, PartialEncoderCapability, RecommendedConcurrency,
};
use zarrs::array::codec::{BloscCodec, Crc32cCodec, GzipCodec, ZstdCodec};
use zarrs::array::{Array, ArrayBytesRaw, ArrayMetadata, BytesRepresentation};
use zarrs::metadata::Configuration;
use zarrs::plugin::{ExtensionAliasesV2, ExtensionAliasesV3, ExtensionName, PluginCreateError, ZarrVersion};
use zarrs::storage::ReadableStorageTraits;

use crate::metadata_check::MAX_CHUNK_SAMPLES;

/// Output bound of a chunk whose decoded size the metadata does not fix (bytes): the largest chunk voxstream reads,
/// in 8-byte samples.
pub const UNKNOWN_SIZE_BOUND: u64 = MAX_CHUNK_SAMPLES * 8;

/// How a [`StrictDecode`] decodes.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
enum Decoding {
    /// zstd, bounded by the decoded size.
    Zstd,
    /// gzip, bounded by the decoded size.
    Gzip,
    /// blosc: the header's declared size checked against the decoded size, then zarrs's decoder.
    Blosc,
    /// zarrs's own whole-chunk decoding, also when zarrs asks for a partial decoder (`crc32c`: verified).
    Whole,
}

/// A zarrs bytes-to-bytes codec decoded strictly (see the module's documentation).
#[derive(Debug)]
struct StrictDecode {
    /// zarrs's codec: names, configuration and encoding.
    inner: Arc<dyn BytesToBytesCodecTraits>,
    decoding: Decoding,
}

/// Decodes `encoded` (zstd or gzip) into at most `bound` bytes; an error as soon as the output would pass it.
fn decode_bounded(decoding: Decoding, encoded: &[u8], bound: u64) -> Result<Vec<u8>, CodecError> {
    let too_large = || {
        CodecError::Other(format!(
            "a chunk inflates past the {bound} bytes it decodes to (a decompression bomb, or corrupt): refused"
        ))
    };
    let mut reader: Box<dyn Read + '_> = match decoding {
        Decoding::Zstd => Box::new(zstd::stream::read::Decoder::with_buffer(encoded)?),
        Decoding::Gzip => Box::new(flate2::read::GzDecoder::new(encoded)),
        Decoding::Blosc | Decoding::Whole => return Err(CodecError::Other("not a streaming decompressor".into())),
    };
    // The bound comes from validated metadata (a brick's size, or a chunk within MAX_CHUNK_SAMPLES): reserving it is
    // what a well-formed chunk takes anyway; unknown sizes grow as they decode.
    let reserve = if bound == UNKNOWN_SIZE_BOUND { 0 } else { bound };
    let mut out = Vec::with_capacity(usize::try_from(reserve).map_err(|_| too_large())?);
    (&mut reader).take(bound.saturating_add(1)).read_to_end(&mut out)?;
    if out.len() as u64 > bound {
        return Err(too_large());
    }
    Ok(out)
}

/// Length of c-blosc's chunk header (bytes).
const BLOSC_HEADER_BYTES: usize = 16;

/// Checks a blosc chunk's declared decoded size (its header's `nbytes`) against `bound` before anything is allocated.
fn check_blosc_header(encoded: &[u8], bound: u64) -> Result<(), CodecError> {
    let Some(header) = encoded.get(..BLOSC_HEADER_BYTES) else {
        return Err(CodecError::Other(format!(
            "a blosc chunk of {} bytes is shorter than blosc's {BLOSC_HEADER_BYTES}-byte header (corrupt): refused",
            encoded.len()
        )));
    };
    let declared = u32::from_le_bytes([header[4], header[5], header[6], header[7]]);
    if u64::from(declared) > bound {
        return Err(CodecError::Other(format!(
            "a blosc chunk declares {declared} bytes, past the {bound} bytes it decodes to \
             (a decompression bomb, or corrupt): refused"
        )));
    }
    Ok(())
}

impl CodecTraits for StrictDecode {
    fn as_any(&self) -> &dyn std::any::Any {
        self
    }

    fn configuration(&self, version: ZarrVersion, options: &CodecMetadataOptions) -> Option<Configuration> {
        self.inner.configuration(version, options)
    }

    fn partial_decoder_capability(&self) -> PartialDecoderCapability {
        // Chunks are decoded whole (the trait's default partial decoder), never read in part.
        PartialDecoderCapability { partial_read: false, partial_decode: false }
    }

    fn partial_encoder_capability(&self) -> PartialEncoderCapability {
        self.inner.partial_encoder_capability()
    }
}

impl ExtensionName for StrictDecode {
    fn name(&self, version: ZarrVersion) -> Option<Cow<'static, str>> {
        self.inner.name(version)
    }
}

impl BytesToBytesCodecTraits for StrictDecode {
    fn into_dyn(self: Arc<Self>) -> Arc<dyn BytesToBytesCodecTraits> {
        self
    }

    fn recommended_concurrency(
        &self,
        decoded_representation: &BytesRepresentation,
    ) -> Result<RecommendedConcurrency, CodecError> {
        self.inner.recommended_concurrency(decoded_representation)
    }

    fn encoded_representation(&self, decoded_representation: &BytesRepresentation) -> BytesRepresentation {
        self.inner.encoded_representation(decoded_representation)
    }

    fn encode<'a>(
        &self,
        decoded_value: ArrayBytesRaw<'a>,
        options: &CodecOptions,
    ) -> Result<ArrayBytesRaw<'a>, CodecError> {
        self.inner.encode(decoded_value, options)
    }

    fn decode<'a>(
        &self,
        encoded_value: ArrayBytesRaw<'a>,
        decoded_representation: &BytesRepresentation,
        options: &CodecOptions,
    ) -> Result<ArrayBytesRaw<'a>, CodecError> {
        let bound = decoded_representation.size().unwrap_or(UNKNOWN_SIZE_BOUND).min(UNKNOWN_SIZE_BOUND);
        match self.decoding {
            Decoding::Whole => self.inner.decode(encoded_value, decoded_representation, options),
            Decoding::Blosc => {
                check_blosc_header(&encoded_value, bound)?;
                self.inner.decode(encoded_value, decoded_representation, options)
            }
            Decoding::Zstd | Decoding::Gzip => decode_bounded(self.decoding, &encoded_value, bound).map(Cow::Owned),
        }
    }
}

/// Wraps the codec zarrs made from the metadata.
fn strict(decoding: Decoding, codec: Result<Codec, PluginCreateError>) -> Result<Codec, PluginCreateError> {
    match codec? {
        Codec::BytesToBytes(inner) => Ok(Codec::BytesToBytes(Arc::new(StrictDecode { inner, decoding }))),
        other => Ok(other),
    }
}

/// `array` as opened, or, for a Zarr v2 array with a blosc compressor or filter, the same array re-created from its
/// metadata converted to v3, so that its blosc decoder is the strict one (see the module's documentation).
pub fn with_strict_blosc(
    array: Array<dyn ReadableStorageTraits>,
    storage: Arc<dyn ReadableStorageTraits>,
) -> Result<Array<dyn ReadableStorageTraits>, String> {
    let ArrayMetadata::V2(v2) = array.metadata() else { return Ok(array) };
    let blosc = v2.compressor.iter().chain(v2.filters.iter().flatten()).any(|c| BloscCodec::matches_name_v2(c.id()));
    if !blosc {
        return Ok(array);
    }
    let v3 = zarrs::convert::array_metadata_v2_to_v3(v2).map_err(|e| e.to_string())?;
    Array::new_with_metadata(storage, array.path().as_str(), ArrayMetadata::V3(v3)).map_err(|e| e.to_string())
}

/// Installs the strict `zstd`, `gzip`, `blosc` and `crc32c` decoders for every array opened afterwards (once per process).
pub fn register() {
    use zarrs::array::codec::api::{register_codec_v2, register_codec_v3, CodecRuntimePluginV2, CodecRuntimePluginV3};
    static REGISTERED: Once = Once::new();
    REGISTERED.call_once(|| {
        register_codec_v3(CodecRuntimePluginV3::new(ZstdCodec::matches_name_v3, |metadata| {
            strict(Decoding::Zstd, <ZstdCodec as CodecTraitsV3>::create(metadata))
        }));
        register_codec_v2(CodecRuntimePluginV2::new(ZstdCodec::matches_name_v2, |metadata| {
            strict(Decoding::Zstd, <ZstdCodec as CodecTraitsV2>::create(metadata))
        }));
        register_codec_v3(CodecRuntimePluginV3::new(GzipCodec::matches_name_v3, |metadata| {
            strict(Decoding::Gzip, <GzipCodec as CodecTraitsV3>::create(metadata))
        }));
        register_codec_v2(CodecRuntimePluginV2::new(GzipCodec::matches_name_v2, |metadata| {
            strict(Decoding::Gzip, <GzipCodec as CodecTraitsV2>::create(metadata))
        }));
        register_codec_v3(CodecRuntimePluginV3::new(BloscCodec::matches_name_v3, |metadata| {
            strict(Decoding::Blosc, <BloscCodec as CodecTraitsV3>::create(metadata))
        }));
        register_codec_v2(CodecRuntimePluginV2::new(BloscCodec::matches_name_v2, |metadata| {
            strict(Decoding::Blosc, <BloscCodec as CodecTraitsV2>::create(metadata))
        }));
        register_codec_v3(CodecRuntimePluginV3::new(Crc32cCodec::matches_name_v3, |metadata| {
            strict(Decoding::Whole, <Crc32cCodec as CodecTraitsV3>::create(metadata))
        }));
        register_codec_v2(CodecRuntimePluginV2::new(Crc32cCodec::matches_name_v2, |metadata| {
            strict(Decoding::Whole, <Crc32cCodec as CodecTraitsV2>::create(metadata))
        }));
        crate::wavelet_codec::register();
    });
}

#[cfg(test)]
mod tests {
    use super::*;

    fn gzip(bytes: &[u8]) -> Vec<u8> {
        use std::io::Write;
        let mut encoder = flate2::write::GzEncoder::new(Vec::new(), flate2::Compression::default());
        encoder.write_all(bytes).unwrap();
        encoder.finish().unwrap()
    }

    #[test]
    fn chunks_decode_up_to_their_size_and_bombs_stop_at_it() {
        let samples = vec![7u8; 4096];
        let bomb = vec![0u8; 64 << 20];
        for decoding in [Decoding::Zstd, Decoding::Gzip] {
            let encode = |bytes: &[u8]| match decoding {
                Decoding::Gzip => gzip(bytes),
                _ => zstd::encode_all(bytes, 3).unwrap(),
            };
            assert_eq!(decode_bounded(decoding, &encode(&samples), 4096).unwrap(), samples, "{decoding:?}");
            let error = decode_bounded(decoding, &encode(&bomb), 4096).unwrap_err().to_string();
            assert!(error.contains("inflates past the 4096 bytes"), "{decoding:?}: {error}");
            assert!(decode_bounded(decoding, &encode(&samples), 4095).is_err(), "{decoding:?}: one byte over");
        }
    }

    #[test]
    fn registered_codecs_replace_zarrs_decoders_by_name() {
        register();
        let metadata: zarrs::metadata::v3::MetadataV3 =
            serde_json::from_str(r#"{"name": "zstd", "configuration": {"level": 3, "checksum": false}}"#).unwrap();
        let Codec::BytesToBytes(codec) = Codec::from_metadata(&metadata).unwrap() else {
            panic!("zstd is a bytes-to-bytes codec");
        };
        let bomb = zstd::encode_all(&vec![0u8; 1 << 20][..], 3).unwrap();
        let options = CodecOptions::default();
        let error = codec.decode(Cow::Owned(bomb), &BytesRepresentation::FixedSize(1000), &options).unwrap_err();
        assert!(error.to_string().contains("inflates past the 1000 bytes"), "{error}");
        assert_eq!(codec.name(ZarrVersion::V3).as_deref(), Some("zstd"), "the metadata it writes is zarrs's");
    }

    #[test]
    fn blosc_chunks_decode_up_to_their_size_and_bombs_are_refused_by_their_header() {
        register();
        let metadata: zarrs::metadata::v3::MetadataV3 = serde_json::from_str(
            r#"{"name": "blosc", "configuration": {"cname": "lz4", "clevel": 9, "shuffle": "noshuffle",
                "blocksize": 0}}"#,
        )
        .unwrap();
        let Codec::BytesToBytes(codec) = Codec::from_metadata(&metadata).unwrap() else {
            panic!("blosc is a bytes-to-bytes codec");
        };
        let options = CodecOptions::default();
        let samples: Vec<u8> = (0..4096u32).map(|i| (i * 7 % 251) as u8).collect();
        let encoded = codec.encode(Cow::Borrowed(&samples), &options).unwrap().into_owned();
        let decoded = codec.decode(Cow::Borrowed(&encoded), &BytesRepresentation::FixedSize(4096), &options).unwrap();
        assert_eq!(decoded.as_ref(), &samples[..]);
        // 64 MiB of zeros is a few hundred kilobytes of blosc; decoded as a 4096-byte brick it is refused unread.
        let bomb = codec.encode(Cow::Owned(vec![0u8; 64 << 20]), &options).unwrap().into_owned();
        assert!(bomb.len() < 1 << 20, "the bomb is small: {} bytes", bomb.len());
        let error = codec.decode(Cow::Owned(bomb), &BytesRepresentation::FixedSize(4096), &options).unwrap_err();
        assert!(error.to_string().contains("declares 67108864 bytes, past the 4096 bytes"), "{error}");
        let error = codec.decode(Cow::Borrowed(&encoded), &BytesRepresentation::FixedSize(4095), &options).unwrap_err();
        assert!(error.to_string().contains("past the 4095 bytes"), "one byte over: {error}");
        let error = codec.decode(Cow::Borrowed(&encoded[..10]), &BytesRepresentation::FixedSize(4096), &options);
        assert!(error.unwrap_err().to_string().contains("shorter than blosc's 16-byte header"));
    }
}
