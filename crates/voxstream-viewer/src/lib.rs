//! # voxstream-viewer: fly through a volume larger than memory, edit its transfer function, see what is resident
//!
//! `voxstream view SOURCE` opens this window over the same frame loop as `voxstream render`
//! ([`voxstream_engine::Session`]): rays ask for data, the cache manager serves a bounded number of requests per
//! frame, coarser data stands in and detail fades in (GigaVoxels [P09] §5's interactive frames, Thiele et al.'s
//! blending). The parts:
//!
//! - [`close_on_signal`]: `SIGTERM`/`SIGINT` close the window as its close button does (`--stats` is written);
//! - [`render_worker`]: the render thread that owns the session, so the window never blocks;
//! - [`app`]: the window (image, controls, status line), reduced resolution while moving, full size at rest;
//! - [`orbit`]: orbit, pan, zoom and fly, converted to and from the renderer's camera;
//! - [`tf_editor`] over [`histogram`]: control points drawn over the source's value histogram;
//! - [`value_axis`]: that histogram's value axis, labelled in data units;
//! - [`files`]: screenshots, cameras and transfer functions saved for `voxstream render --camera/--tf`;
//! - [`script`]: scripted sessions for demonstrations and end-to-end tests.
//!
//! The window is eframe (egui on winit) with its OpenGL backend; the session's renderer (the CPU ray caster, or the
//! GPU one with `--backend gpu`) draws the image off-screen and OpenGL only shows it.

pub mod app;
pub mod close_on_signal;
pub mod error;
pub mod files;
pub mod histogram;
pub mod orbit;
pub mod render_worker;
pub mod script;
pub mod tf_editor;
pub mod value_axis;

use std::sync::atomic::{AtomicUsize, Ordering};
use std::sync::{Arc, Mutex, PoisonError};

pub use app::{ViewerApp, ViewerConfig};
pub use error::ViewerError;
pub use render_worker::Refinement;
use voxstream_core::Producer;
use voxstream_engine::{FrameRenderer, Session};

/// Room around the image for the controls and the status line (points).
const CONTROLS_WIDTH: f32 = 360.0;

/// Whether a display server is named in the environment (`DISPLAY` or `WAYLAND_DISPLAY`).
pub fn has_display() -> bool {
    ["DISPLAY", "WAYLAND_DISPLAY"].iter().any(|v| std::env::var_os(v).is_some_and(|s| !s.is_empty()))
}

/// How a viewer session ended, when no error did.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct ViewerSummary {
    /// Bricks that could not be read (each reported once on stderr; coarser data stood in): `voxstream view` then
    /// exits as `render` does for an incomplete image.
    pub failed_bricks: usize,
}

/// Opens the viewer's window on `session` and returns when it is closed (by its close button, `Esc`, `Ctrl+Q`, a
/// script's `quit`, or `SIGTERM`/`SIGINT`: all of them write `--stats`): `Err` when no window could be opened or a
/// script failed.
pub fn run_viewer<P, R>(session: Session<P, R>, config: ViewerConfig) -> Result<ViewerSummary, ViewerError>
where
    P: Producer + 'static,
    R: FrameRenderer + Send + 'static,
{
    if !has_display() {
        return Err(ViewerError::NoDisplay);
    }
    let failure = Arc::new(Mutex::new(None));
    let app_failure = failure.clone();
    let failed_bricks = Arc::new(AtomicUsize::new(0));
    let app_failed_bricks = failed_bricks.clone();
    let size = [
        (config.settings.width as f32).clamp(320.0, 1600.0) + CONTROLS_WIDTH,
        (config.settings.height as f32).clamp(240.0, 1000.0) + 60.0,
    ];
    let options = eframe::NativeOptions {
        viewport: eframe::egui::ViewportBuilder::default().with_inner_size(size).with_title(config.title.clone()),
        ..Default::default()
    };
    let title = config.title.clone();
    let mut config = Some(config);
    // Held until the window has closed (from then on the signals terminate, as without it).
    let close_on_signal = Arc::new(Mutex::new(None));
    let app_close_on_signal = close_on_signal.clone();
    let result = eframe::run_native(
        &title,
        options,
        Box::new(move |cc| {
            let context = cc.egui_ctx.clone();
            let config = config.take().ok_or("the viewer was started twice")?;
            // SIGTERM and SIGINT close the window as its close button does: `on_exit` writes `--stats`.
            let closing = cc.egui_ctx.clone();
            let guard = close_on_signal::CloseOnSignal::install(move || {
                closing.send_viewport_cmd(eframe::egui::ViewportCommand::Close);
                closing.request_repaint();
            });
            match guard {
                Ok(guard) => *app_close_on_signal.lock().unwrap_or_else(PoisonError::into_inner) = Some(guard),
                Err(error) => eprintln!("warning: SIGTERM will end the viewer without writing --stats: {error}"),
            }
            let worker =
                render_worker::RenderWorker::start(session, config.refinement, move || context.request_repaint())?;
            Ok(Box::new(ViewerApp::new(worker, config, app_failure, app_failed_bricks)))
        }),
    )
    .map_err(|e| ViewerError::Window(e.to_string()));
    drop(close_on_signal.lock().unwrap_or_else(PoisonError::into_inner).take());
    result?;
    let failure = failure.lock().unwrap_or_else(PoisonError::into_inner).take();
    match failure {
        Some(message) => Err(ViewerError::Script(message)),
        None => Ok(ViewerSummary { failed_bricks: failed_bricks.load(Ordering::Relaxed) }),
    }
}
