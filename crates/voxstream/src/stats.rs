//! The `--stats` JSON: what a run did, frame by frame and in total.

use serde::Serialize;

/// Statistics of a `voxstream render` run.
#[derive(Clone, Debug, Default, Serialize)]
pub struct RunStats {
    /// Scene or source rendered.
    pub source: String,
    /// "converged" or "interactive".
    pub mode: String,
    /// Output frames written.
    pub frames: usize,
    /// Whether the last frame was complete (no ray missed anything).
    pub converged: bool,
    /// Wall time per output frame (rendering and production), ms.
    pub frame_ms: Vec<f64>,
    /// Render passes per output frame.
    pub passes: Vec<u32>,
    /// Rays traced, all passes.
    pub rays: u64,
    /// Samples taken, all passes.
    pub samples: u64,
    /// Distinct requests, all passes.
    pub requests: u64,
    /// Bricks produced.
    pub bricks_produced: u64,
    /// Of the requests served, steps no ray asked for that kept the working set restricted (level blending on:
    /// Thiele et al.'s forced splits).
    pub forced_steps: u64,
    /// Evictions that broke the restriction because the memory budget needed them.
    pub restriction_yielded: u64,
    /// Bricks resident at the end.
    pub bricks_resident: u64,
    /// Nodes resident at the end.
    pub nodes_resident: u64,
    /// Peak bytes of the node and brick pools.
    pub resident_bytes_peak: u64,
    /// The pools' budget.
    pub budget_bytes: u64,
    /// Peak resident set size of the whole process, if known.
    pub peak_rss_bytes: Option<u64>,
    /// Producer failures (bricks drawn from their ancestors instead).
    pub producer_failures: usize,
    /// Worker threads used.
    pub threads: usize,
    /// The renderer and its device (`--backend`): e.g. "gpu: llvmpipe (LLVM 15.0.6, 256 bits) (CPU emulation, …)".
    pub backend: String,
    /// What the renderer warned of its device, if anything: a GPU adapter that is a CPU emulation (lavapipe), with
    /// `--backend cpu` suggested.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub backend_warning: Option<String>,
    /// Bytes of tiles and bricks uploaded to the renderer's memory (the GPU's; 0 on the CPU).
    pub bytes_uploaded: u64,
    /// Bytes read from files while rendering (stores only: compressed shards and metadata).
    pub file_bytes_read: Option<u64>,
    /// Bytes read from files while opening the store, before rendering (its metadata; for other tools' OME-Zarr,
    /// also the scan of one level's stored samples for its value range, unless `--value-range` is given).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub file_bytes_read_opening: Option<u64>,
    /// Stores: the host caches' budgets (decoded bricks, and bricks as stored: compressed), and what the compressed
    /// one held at the end and served (reads not made again).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub host_caches: Option<voxstream_store::store_reader::HostCaches>,
    /// A remote store's requests, bytes, retries and failures since it was opened (absent for local sources).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub remote: Option<RemoteStats>,
    /// Bytes of the bricks resident at the end (borders excluded, in the source's sample type): what the frame used.
    pub brick_bytes_used: Option<u64>,
    /// Milliseconds until the first image was complete enough to write (the first frame).
    pub first_frame_ms: Option<f64>,
    /// The first camera rendered (the source's default unless flags or a path gave one): a camera path made of it
    /// reproduces the view.
    pub camera: Option<voxstream_render::Camera>,
    /// Whether level blending was on (interactive mode with `--blending on`).
    pub blending: bool,
    /// Interactive mode: popping and seams of the frames against the converged images at the same cameras (8-bit
    /// levels; see `voxstream_engine::popping`).
    pub popping: Option<voxstream_engine::PoppingSummary>,
}

/// What a remote store did (`--stats`'s `remote`).
#[derive(Debug, Clone, Copy, Default, serde::Serialize, serde::Deserialize)]
pub struct RemoteStats {
    /// Requests answered (bytes, or a definite "not found").
    pub requests: u64,
    /// Bytes received in bodies used.
    pub bytes: u64,
    /// Requests sent again after a short body or a transport error (the client's own retries of 5xx, 429 and
    /// timeouts come on top).
    pub retries: u64,
    /// Reads that failed after every retry (their bricks are reported as failed; ancestors stand in).
    pub failures: u64,
    /// Reads answered from `--cache-dir`.
    pub cache_hits: u64,
}

impl From<voxstream_store::remote::RemoteCounts> for RemoteStats {
    fn from(c: voxstream_store::remote::RemoteCounts) -> Self {
        RemoteStats {
            requests: c.requests,
            bytes: c.bytes,
            retries: c.retries,
            failures: c.failures,
            cache_hits: c.cache_hits,
        }
    }
}
