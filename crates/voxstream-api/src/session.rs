//! From an opened source to frames: a session over the source's producer, drawn by the chosen backend within the
//! memory budget ([`start_session`]), and [`Volume`], which keeps one such session per source and reuses it while
//! the budget, image size and backend stay the same (so a second render of a store starts warm).
//!
//! The loop itself (camera → renderer → feedback → cache manager → producer → pools) is
//! [`voxstream_engine::Session`]; this module only wires it up as every front end needs it.

use std::ops::ControlFlow;

use anyhow::Result;
use voxstream_core::Producer;
use voxstream_engine::{FrameRenderer, FrameResult, LoopLimits, MemoryBudget, MemoryPlan, Mode, PassProgress, Session};

use crate::backend::{open_renderer, Backend, GpuFilter};
use crate::render_budget::{check_budget, plan_budget};
use crate::source::{open, Source, SourceMeta, SourceOptions};
use crate::view::{prepare_view, PreparedView, ViewOptions};

/// A session over any source, drawn by any backend.
pub type FrameSession = Session<Box<dyn Producer>, Box<dyn FrameRenderer + Send>>;

/// How a session renders: its budget, backend and loop limits. The defaults are `voxstream render`'s.
#[derive(Clone, Debug, PartialEq)]
pub struct SessionOptions {
    /// The whole memory budget, MiB (`--budget-mb`).
    pub budget_mb: u64,
    /// The renderer (`--backend`).
    pub backend: Backend,
    /// The GPU renderer's brick filtering (`--gpu-filter`).
    pub gpu_filter: GpuFilter,
    /// Requests an interactive frame serves (`--requests-per-frame`).
    pub requests_per_frame: usize,
    /// Interactive frames blend arriving bricks in over `fade_frames` frames (Thiele et al.; `--blending`).
    pub blending: bool,
    /// Frames a fade lasts (`--fade-frames`).
    pub fade_frames: u32,
}

impl Default for SessionOptions {
    fn default() -> Self {
        SessionOptions {
            budget_mb: 256,
            backend: Backend::Cpu,
            gpu_filter: GpuFilter::Auto,
            requests_per_frame: 1024,
            blending: true,
            fade_frames: voxstream_core::DEFAULT_FADE_FRAMES,
        }
    }
}

impl SessionOptions {
    /// The engine's loop limits these options ask for.
    pub fn limits(&self) -> LoopLimits {
        LoopLimits {
            requests_per_frame: self.requests_per_frame,
            blending_fade_frames: self.blending.then_some(self.fade_frames),
            ..LoopLimits::default()
        }
    }
}

/// Starts a session over `producer` (of the source `meta` describes) for the prepared view, within `budget`.
pub fn start_session(
    producer: Box<dyn Producer>,
    meta: &SourceMeta,
    prepared: &PreparedView,
    options: &SessionOptions,
    budget: &MemoryBudget,
) -> Result<(FrameSession, MemoryPlan)> {
    let plan = plan_budget(budget, &producer.shape(), meta.producer_cache_bytes)?;
    let renderer = open_renderer(options.backend, options.gpu_filter)?;
    let session = Session::with_renderer(
        renderer,
        producer,
        &prepared.transfer_function,
        prepared.settings.clone(),
        plan.pool_bytes,
        options.limits(),
        meta.value_range,
    )?;
    Ok((session, plan))
}

/// One source, opened by name, and the session that last drew it.
pub struct Volume {
    name: String,
    source_options: SourceOptions,
    meta: SourceMeta,
    /// The producer until a render moves it into a session.
    producer: Option<Box<dyn Producer>>,
    /// The budget and image size the source was opened for (a store's cache and default camera depend on them).
    opened_for: (u64, u32, u32),
    /// The session, and the budget, image size and options it was made for.
    session: Option<(SessionKey, FrameSession)>,
    /// The settings and transfer function the session holds (changing them restarts the sparse gathering of a
    /// converged frame, so they are only set when they change).
    applied: Option<(voxstream_render::RenderSettings, voxstream_render::TransferFunction)>,
}

/// What a session cannot change once made: the budget (split at open between the store's cache and the pools), the
/// image size (part of the budget), the backend and the loop limits.
#[derive(Clone, Debug, PartialEq)]
struct SessionKey {
    options: SessionOptions,
    width: u32,
    height: u32,
    /// The view's region: it narrows the placement's clip box, which a session keeps.
    region: Option<[[u64; 3]; 2]>,
}

impl Volume {
    /// Opens `name` (a built-in scene, a mesh or particle file, a store's folder or URL) for images of
    /// `options.width × options.height` within `budget_mb`, checking it now.
    pub fn open(name: &str, options: &SourceOptions, budget_mb: u64) -> Result<Volume> {
        let budget = check_budget(budget_mb, options.width, options.height, "size")?;
        let Source { producer, meta } = open(name, options, &budget)?;
        Ok(Volume {
            name: name.to_string(),
            source_options: options.clone(),
            meta,
            producer: Some(producer),
            opened_for: (budget_mb, options.width, options.height),
            session: None,
            applied: None,
        })
    }

    /// The source's name, defaults and data range.
    pub fn meta(&self) -> &SourceMeta {
        &self.meta
    }

    /// Renders one frame of `view` in `mode`. `observe` hears after each pass and may stop the frame
    /// ([`ControlFlow::Break`]: the result is then marked interrupted). The session is kept for the next frame
    /// with the same budget, image size, options and region; a different budget, image size or region opens the
    /// source again (as a new `voxstream render` would), so that the image is the CLI's for the same arguments.
    pub fn render(
        &mut self,
        view: &ViewOptions,
        options: &SessionOptions,
        mode: Mode,
        observe: &mut dyn FnMut(&PassProgress) -> ControlFlow<()>,
    ) -> Result<(FrameResult, PreparedView)> {
        let key = SessionKey { options: options.clone(), width: view.width, height: view.height, region: view.region };
        if !matches!(&self.session, Some((old, _)) if *old == key) {
            let budget = check_budget(options.budget_mb, view.width, view.height, "size")?;
            let wanted = (options.budget_mb, view.width, view.height);
            let producer = match self.producer.take() {
                Some(producer) if self.opened_for == wanted => producer,
                _ => {
                    self.session = None;
                    let mut source_options = self.source_options.clone();
                    source_options.width = view.width;
                    source_options.height = view.height;
                    let Source { producer, meta } = open(&self.name, &source_options, &budget)?;
                    self.meta = meta;
                    self.opened_for = wanted;
                    producer
                }
            };
            let prepared = prepare_view(view, &self.meta)?;
            let (session, _plan) = start_session(producer, &self.meta, &prepared, options, &budget)?;
            self.session = Some((key, session));
            self.applied = Some((prepared.settings.clone(), prepared.transfer_function.clone()));
        }
        let prepared = prepare_view(view, &self.meta)?;
        let (_, session) = self.session.as_mut().expect("a session was just made or kept");
        let (settings, transfer_function) =
            self.applied.get_or_insert_with(|| (prepared.settings.clone(), prepared.transfer_function.clone()));
        if *settings != prepared.settings {
            session.set_settings(prepared.settings.clone())?;
            *settings = prepared.settings.clone();
        }
        if *transfer_function != prepared.transfer_function {
            session.set_transfer_function(&prepared.transfer_function);
            *transfer_function = prepared.transfer_function.clone();
        }
        let result = session.render_interruptible(&prepared.camera, mode, observe)?;
        Ok((result, prepared))
    }

    /// The session of the last render, if any (its cache, residency and renderer).
    pub fn session(&self) -> Option<&FrameSession> {
        self.session.as_ref().map(|(_, session)| session)
    }
}
