//! zarrs's codecs with strict decoding: `zstd` and `gzip` that stop at the chunk's known size, and `crc32c` that
//! verifies its checksum on every read.
//!
//! zarrs's own zstd decoder allocates whatever the frame header declares (or inflates without end when it declares
//! nothing), and its gzip decoder inflates without end: one brick of a 77 KB shard could inflate to 1 GiB. Every
//! chunk's decoded size is known before decoding (a brick is `brick_size³ ×` sample size; zarrs passes it as the
//! decoded representation), so the output is bounded by it: fixed-size chunks decode into exactly that many bytes,
//! and anything more is an error naming the bound. Chunks of unknown size are bounded by [`UNKNOWN_SIZE_BOUND`].
//!
//! zarrs's `crc32c` verifies the checksum when it decodes a whole chunk, but its partial decoder (the one a shard's
//! bricks are read through) only strips the four bytes: a flipped bit in a brick went unnoticed. Here a brick is
//! always decoded whole (it is read whole anyway), so its checksum is always verified.
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
use zarrs::array::codec::{Crc32cCodec, GzipCodec, ZstdCodec};
use zarrs::array::{ArrayBytesRaw, BytesRepresentation};
use zarrs::metadata::Configuration;
use zarrs::plugin::{ExtensionAliasesV2, ExtensionAliasesV3, ExtensionName, PluginCreateError, ZarrVersion};

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
        Decoding::Whole => return Err(CodecError::Other("not a compressor".into())),
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
        if self.decoding == Decoding::Whole {
            return self.inner.decode(encoded_value, decoded_representation, options);
        }
        let bound = decoded_representation.size().unwrap_or(UNKNOWN_SIZE_BOUND).min(UNKNOWN_SIZE_BOUND);
        decode_bounded(self.decoding, &encoded_value, bound).map(Cow::Owned)
    }
}

/// Wraps the codec zarrs made from the metadata.
fn strict(decoding: Decoding, codec: Result<Codec, PluginCreateError>) -> Result<Codec, PluginCreateError> {
    match codec? {
        Codec::BytesToBytes(inner) => Ok(Codec::BytesToBytes(Arc::new(StrictDecode { inner, decoding }))),
        other => Ok(other),
    }
}

/// Installs the strict `zstd`, `gzip` and `crc32c` decoders for every array opened afterwards (once per process).
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
        register_codec_v3(CodecRuntimePluginV3::new(Crc32cCodec::matches_name_v3, |metadata| {
            strict(Decoding::Whole, <Crc32cCodec as CodecTraitsV3>::create(metadata))
        }));
        register_codec_v2(CodecRuntimePluginV2::new(Crc32cCodec::matches_name_v2, |metadata| {
            strict(Decoding::Whole, <Crc32cCodec as CodecTraitsV2>::create(metadata))
        }));
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
}
