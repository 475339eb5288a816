//! Decompression that stops at the chunk's known size: zarrs's `zstd` and `gzip` codecs, with a decoder that refuses
//! a chunk the moment its output would pass the size the array's metadata gives it.
//!
//! zarrs's own zstd decoder allocates whatever the frame header declares (or inflates without end when it declares
//! nothing), and its gzip decoder inflates without end: one brick of a 77 KB shard could inflate to 1 GiB. Every
//! chunk's decoded size is known before decoding (a brick is `brick_size³ ×` sample size; zarrs passes it as the
//! decoded representation), so the output is bounded by it: fixed-size chunks decode into exactly that many bytes,
//! and anything more is an error naming the bound. Chunks of unknown size are bounded by [`UNKNOWN_SIZE_BOUND`].
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
use zarrs::array::codec::{GzipCodec, ZstdCodec};
use zarrs::array::{ArrayBytesRaw, BytesRepresentation};
use zarrs::metadata::Configuration;
use zarrs::plugin::{ExtensionAliasesV2, ExtensionAliasesV3, ExtensionName, PluginCreateError, ZarrVersion};

use crate::metadata_check::MAX_CHUNK_SAMPLES;

/// Output bound of a chunk whose decoded size the metadata does not fix (bytes): the largest chunk voxstream reads,
/// in 8-byte samples.
pub const UNKNOWN_SIZE_BOUND: u64 = MAX_CHUNK_SAMPLES * 8;

/// Which decompressor a [`BoundedDecode`] runs.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
enum Compression {
    Zstd,
    Gzip,
}

/// A zarrs bytes-to-bytes codec whose decoding is bounded by the chunk's decoded size.
#[derive(Debug)]
struct BoundedDecode {
    /// zarrs's codec: names, configuration and encoding.
    inner: Arc<dyn BytesToBytesCodecTraits>,
    compression: Compression,
}

/// Decodes `encoded` (`compression`) into at most `bound` bytes; an error as soon as the output would pass it.
fn decode_bounded(compression: Compression, encoded: &[u8], bound: u64) -> Result<Vec<u8>, CodecError> {
    let too_large = || {
        CodecError::Other(format!(
            "a chunk inflates past the {bound} bytes it decodes to (a decompression bomb, or corrupt): refused"
        ))
    };
    let mut reader: Box<dyn Read + '_> = match compression {
        Compression::Zstd => Box::new(zstd::stream::read::Decoder::with_buffer(encoded)?),
        Compression::Gzip => Box::new(flate2::read::GzDecoder::new(encoded)),
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

impl CodecTraits for BoundedDecode {
    fn as_any(&self) -> &dyn std::any::Any {
        self
    }

    fn configuration(&self, version: ZarrVersion, options: &CodecMetadataOptions) -> Option<Configuration> {
        self.inner.configuration(version, options)
    }

    fn partial_decoder_capability(&self) -> PartialDecoderCapability {
        self.inner.partial_decoder_capability()
    }

    fn partial_encoder_capability(&self) -> PartialEncoderCapability {
        self.inner.partial_encoder_capability()
    }
}

impl ExtensionName for BoundedDecode {
    fn name(&self, version: ZarrVersion) -> Option<Cow<'static, str>> {
        self.inner.name(version)
    }
}

impl BytesToBytesCodecTraits for BoundedDecode {
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
        _options: &CodecOptions,
    ) -> Result<ArrayBytesRaw<'a>, CodecError> {
        let bound = decoded_representation.size().unwrap_or(UNKNOWN_SIZE_BOUND).min(UNKNOWN_SIZE_BOUND);
        decode_bounded(self.compression, &encoded_value, bound).map(Cow::Owned)
    }
}

/// Wraps the codec zarrs made from the metadata.
fn bounded(compression: Compression, codec: Result<Codec, PluginCreateError>) -> Result<Codec, PluginCreateError> {
    match codec? {
        Codec::BytesToBytes(inner) => Ok(Codec::BytesToBytes(Arc::new(BoundedDecode { inner, compression }))),
        other => Ok(other),
    }
}

/// Installs the bounded `zstd` and `gzip` decoders for every array opened afterwards (once per process).
pub fn register() {
    use zarrs::array::codec::api::{register_codec_v2, register_codec_v3, CodecRuntimePluginV2, CodecRuntimePluginV3};
    static REGISTERED: Once = Once::new();
    REGISTERED.call_once(|| {
        register_codec_v3(CodecRuntimePluginV3::new(ZstdCodec::matches_name_v3, |metadata| {
            bounded(Compression::Zstd, <ZstdCodec as CodecTraitsV3>::create(metadata))
        }));
        register_codec_v2(CodecRuntimePluginV2::new(ZstdCodec::matches_name_v2, |metadata| {
            bounded(Compression::Zstd, <ZstdCodec as CodecTraitsV2>::create(metadata))
        }));
        register_codec_v3(CodecRuntimePluginV3::new(GzipCodec::matches_name_v3, |metadata| {
            bounded(Compression::Gzip, <GzipCodec as CodecTraitsV3>::create(metadata))
        }));
        register_codec_v2(CodecRuntimePluginV2::new(GzipCodec::matches_name_v2, |metadata| {
            bounded(Compression::Gzip, <GzipCodec as CodecTraitsV2>::create(metadata))
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
        for compression in [Compression::Zstd, Compression::Gzip] {
            let encode = |bytes: &[u8]| match compression {
                Compression::Zstd => zstd::encode_all(bytes, 3).unwrap(),
                Compression::Gzip => gzip(bytes),
            };
            assert_eq!(decode_bounded(compression, &encode(&samples), 4096).unwrap(), samples, "{compression:?}");
            let error = decode_bounded(compression, &encode(&bomb), 4096).unwrap_err().to_string();
            assert!(error.contains("inflates past the 4096 bytes"), "{compression:?}: {error}");
            assert!(decode_bounded(compression, &encode(&samples), 4095).is_err(), "{compression:?}: one byte over");
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
