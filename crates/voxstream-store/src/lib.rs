//! # voxstream-store: real volumes, out of core
//!
//! Where it sits in the loop (camera → renderer → feedback → cache manager → **producers** → pools): the
//! [`StoreProducer`](store_producer::StoreProducer) answers the cache manager's requests by reading bricks from an
//! on-disk OME-Zarr store, which [`import_volume`](import::import_volume) builds once from a volume file.
//!
//! - [`formats`]: importers (raw, NRRD, NIfTI-1, MetaImage, INR, NumPy), read in z slabs.
//! - [`import`]: the streaming pyramid writer (OME-Zarr 0.5 / Zarr v3, sharded, zstd, per-brick min/max).
//! - [`checked_store`] and [`strict_codecs`]: every store read checked before it allocates (file kind, byte ranges
//!   against the file's size, decoding bounded by the chunk's size, each brick's CRC-32C verified).
//! - [`store_lock`]: one writer per store (the import lock), and aside folders left by interrupted swaps.
//! - [`store_producer`]: bricks with borders, streamed from the store (GigaVoxels' producer reading from disk;
//!   Reichl's streaming supplier, seed 004 ch. 4).

pub mod checked_store;
pub mod chunk_cache;
pub mod chunk_keys;
pub mod encoded_cache;
pub mod error;
pub mod foreign;
pub mod foreign_axes;
pub mod formats;
pub mod image_planes;
pub mod import;
pub mod layout;
pub mod level_probe;
pub mod level_source;
pub mod metadata;
pub mod metadata_check;
pub mod metadata_files;
pub mod non_finite;
pub mod orientation;
pub mod remote_access;
pub mod shard_import;
pub mod single_flight;
pub mod space_unit;
pub mod store_lock;
pub mod store_producer;
pub mod store_reader;
pub mod stored_chunks;
pub mod strict_codecs;
pub mod synthesis_limit;
pub mod value_histogram;
pub mod value_range;
pub mod volume;
pub mod wavelet_codec;
pub mod world_extent;

pub use error::StoreError;
pub use import::{import_volume, BrickCodec, ImportOptions, ImportReport};
pub use layout::PyramidLayout;
pub use orientation::Orientation;
pub use space_unit::SpaceUnit;
pub use store_producer::{BrickSource, InMemoryVolume, StoreProducer};
pub use store_reader::StoreReader;
pub use volume::{DType, VolumeInfo, VolumeSource};
pub use voxstream_remote as remote;
