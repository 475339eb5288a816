//! The window: the image, the controls, the status line, and the scripted session, on the window's thread. It only
//! posts requests to the [`RenderWorker`] and shows what comes back, so it never waits for a frame or a brick.
//!
//! While the view moves, frames are drawn at a fraction of the render size (an eighth of the edge at first, halved
//! again while they take longer than [`MOVING_FRAME_MS`], doubled below an eighth of it); once the pointer and keys
//! rest for [`REST_AFTER`], the full size is asked for and
//! refined until final (GigaVoxels' interactive frames with Thiele et al.'s level blending, as `voxstream render
//! --mode interactive` draws them).

use std::collections::VecDeque;
use std::path::PathBuf;
use std::sync::atomic::{AtomicUsize, Ordering};
use std::sync::{Arc, Mutex};
use std::time::{Duration, Instant};

use eframe::egui::{self, Color32, ColorImage, TextureHandle, TextureOptions};
use voxstream_render::annotations::{annotate_rgb8, AnnotationContext, Annotations};
use voxstream_render::{Camera, RenderSettings, TransferFunction};

use crate::files::write_output;
use crate::histogram::SampledHistogram;
use crate::orbit::OrbitCamera;
use crate::render_worker::{RenderWorker, ShownFrame, ViewRequest, WorkerEvent};
use crate::script::Script;
use crate::tf_editor::TransferFunctionEditor;

mod panels;
mod scripting;

/// Time without input after which the view is at rest and drawn at full size.
pub const REST_AFTER: Duration = Duration::from_millis(250);

/// Frame time above which moving frames are drawn smaller (and below an eighth of which, larger again): 40 ms, so that
/// moving frames stay within a 50 ms budget (20 frames/s) with room for a frame that loads more than most.
pub const MOVING_FRAME_MS: f64 = 40.0;

/// The window over which frames and bricks per second are measured.
const RATE_WINDOW: Duration = Duration::from_secs(3);

/// How often a waiting script looks again (frames arriving wake it too).
const SCRIPT_POLL: Duration = Duration::from_millis(100);
/// The largest pool budget the window offers, MiB: the machine's memory (or the cgroup's limit) where known, never
/// more than `--budget-mb`'s bound.
fn max_budget_mib() -> u64 {
    let machine = voxstream_engine::machine_memory_bytes().map_or(crate::script::MAX_BUDGET_MIB, |b| b >> 20);
    machine.clamp(1, crate::script::MAX_BUDGET_MIB)
}

/// How long `window-screenshot` waits for the window to be read back.
const WINDOW_SHOT_TIMEOUT: Duration = Duration::from_secs(30);

/// Largest divisor of the render size while moving.
const MAX_MOVING_DIVISOR: u32 = 8;

/// Bricks that could not be read named on stderr, at most (as `render`; the count is in the stats and exit status).
const MAX_REPORTED_FAILURES: usize = 20;

/// Degrees of orbit per point dragged.
const ORBIT_DEGREES_PER_POINT: f64 = 0.4;

/// How the viewer was started.
pub struct ViewerConfig {
    /// Window title.
    pub title: String,
    /// The starting camera (also the one `reset` returns to).
    pub camera: Camera,
    /// The starting transfer function.
    pub transfer_function: TransferFunction,
    /// The render settings at full size.
    pub settings: RenderSettings,
    /// The adaptive step's tolerance while no isosurface is drawn (`None`: fixed steps, `view --faithful`); with
    /// isosurfaces, none (their cell walk steps exactly), as `render` does.
    pub volume_adaptive_step: Option<f64>,
    /// Data values the voxel values 0 and 1 stand for.
    pub value_range: [f64; 2],
    /// Transfer-function presets offered besides the starting one.
    pub presets: Vec<(String, TransferFunction)>,
    /// A scripted session to run.
    pub script: Option<Script>,
    /// The pools' budget at start (bytes); the window's budget field changes it.
    pub pool_budget_bytes: u64,
    /// Where to write the frame log when the window closes (`view --stats`).
    pub stats_path: Option<PathBuf>,
    /// How a view at rest is refined.
    pub refinement: crate::render_worker::Refinement,
    /// The renderer drawing the frames, in one line (`FrameRenderer::describe`): in the help overlay and the frame
    /// log.
    pub renderer: String,
    /// What the renderer warned of its device (`FrameRenderer::device_warning`: a CPU emulation of a GPU): shown
    /// in the window's messages and written to the frame log.
    pub renderer_warning: Option<String>,
    /// The colour bar and scale bar drawn over the frames at start (`view --color-bar --scale-bar`; the window's
    /// toggles change them).
    pub annotations: Annotations,
    /// The data's length unit (OME-Zarr name) for the scale bar, where known.
    pub unit: Option<String>,
    /// The source's host caches in a few words, for the status line (stores: the decoded and the compressed brick
    /// caches' budgets and use); asked once a frame.
    pub host_caches: Option<Box<dyn Fn() -> String + Send>>,
}

/// One frame as the window received it (`view --stats`).
#[derive(Clone, Copy, Debug)]
struct FrameLog {
    /// Milliseconds since the window opened.
    at_ms: f64,
    /// Render and production time of the frame.
    frame_ms: f64,
    size: [u32; 2],
    is_final: bool,
    pending: usize,
    bricks_produced: u64,
    /// Pool bytes resident after the frame, and the pools' budget.
    resident_bytes: [u64; 2],
    /// Milliseconds since the last input (pointer, keys or a scripted move), if any.
    since_input_ms: Option<f64>,
}

/// The window's state.
pub struct ViewerApp {
    worker: RenderWorker,
    config: ViewerConfig,
    orbit: OrbitCamera,
    editor: TransferFunctionEditor,
    settings: RenderSettings,
    histogram: Option<SampledHistogram>,
    revision: u64,
    last_request: Option<ViewRequest>,
    last_input: Option<Instant>,
    moving_divisor: u32,
    shown: Option<ShownFrame>,
    texture: Option<TextureHandle>,
    overlay_missing: bool,
    /// The colour bar and scale bar drawn over the frame shown.
    annotations: Annotations,
    /// The pools' budget the renderer is asked for, bytes (`--budget-mb`'s share at start).
    pool_budget_bytes: u64,
    /// The budget field, MiB (applied by its button).
    budget_field_mib: u64,
    /// Where loading is prioritised: the cursor over the image, else the centre (`RenderSettings::focus`).
    focus: [f32; 2],
    show_help: bool,
    messages: Vec<String>,
    frame_times: VecDeque<(Instant, u64)>,
    script: Option<ScriptRun>,
    script_failure: Arc<Mutex<Option<String>>>,
    /// Bricks that could not be read so far (the session reports each once), for the exit status.
    failed_bricks: Arc<AtomicUsize>,
    opened: Instant,
    frame_log: Vec<FrameLog>,
    tf_path: String,
    camera_path: String,
    screenshot_path: String,
}

struct ScriptRun {
    script: Script,
    next: usize,
    started: Instant,
    /// A `window-screenshot` under way: egui's callback leaves the result of writing the file here.
    window_shot: Option<Arc<Mutex<Option<Result<(), String>>>>>,
}

impl ViewerApp {
    /// A window over `worker`; a failing script's message is left in `script_failure`, the count of bricks that
    /// could not be read in `failed_bricks`.
    pub fn new(
        worker: RenderWorker,
        config: ViewerConfig,
        script_failure: Arc<Mutex<Option<String>>>,
        failed_bricks: Arc<AtomicUsize>,
    ) -> ViewerApp {
        let script = config.script.clone().map(|script| ScriptRun {
            script,
            next: 0,
            started: Instant::now(),
            window_shot: None,
        });
        let messages = config.renderer_warning.iter().cloned().collect();
        ViewerApp {
            worker,
            orbit: OrbitCamera::from_camera(&config.camera),
            editor: TransferFunctionEditor::new(&config.transfer_function),
            settings: config.settings.clone(),
            histogram: None,
            revision: 0,
            last_request: None,
            last_input: None,
            // Start small: the first moving frames come before any has been measured.
            moving_divisor: MAX_MOVING_DIVISOR,
            shown: None,
            texture: None,
            overlay_missing: false,
            annotations: config.annotations,
            pool_budget_bytes: config.pool_budget_bytes,
            budget_field_mib: (config.pool_budget_bytes >> 20).max(1),
            focus: [0.5, 0.5],
            show_help: false,
            messages,
            frame_times: VecDeque::new(),
            script,
            script_failure,
            failed_bricks,
            opened: Instant::now(),
            frame_log: Vec::new(),
            tf_path: "transfer-function.json".into(),
            camera_path: "camera.json".into(),
            screenshot_path: "screenshot.png".into(),
            config,
        }
    }

    fn moving(&self) -> bool {
        self.last_input.is_some_and(|t| t.elapsed() < REST_AFTER)
    }

    fn note_input(&mut self) {
        self.last_input = Some(Instant::now());
    }

    /// Back to the starting view (counts as input).
    fn reset_view(&mut self) {
        self.orbit = OrbitCamera::from_camera(&self.config.camera);
        self.note_input();
    }

    /// The request for the current state: full size at rest, smaller while moving.
    fn desired_request(&self) -> ViewRequest {
        let mut settings = self.settings.clone();
        settings.focus = Some(self.focus);
        // Isosurfaces turned on or off in the window: the step choice follows, as `render`'s would.
        settings.adaptive_step = if settings.surfaces.is_empty() { self.config.volume_adaptive_step } else { None };
        settings.preintegrated &= settings.surfaces.is_empty();
        let moving = self.moving();
        if moving {
            settings.width = (settings.width / self.moving_divisor).max(1);
            settings.height = (settings.height / self.moving_divisor).max(1);
        }
        ViewRequest {
            revision: self.revision,
            camera: self.orbit.to_camera(),
            transfer_function: self.editor.transfer_function(),
            settings,
            at_rest: !moving,
            pool_budget_bytes: self.pool_budget_bytes,
        }
    }

    fn post_request_if_changed(&mut self) {
        let mut request = self.desired_request();
        let refining = self.shown.as_ref().is_none_or(|s| !s.is_final || s.revision != self.revision);
        let changed = self.last_request.as_ref().is_none_or(|last| {
            let mut unfocused = last.settings.clone();
            unfocused.focus = request.settings.focus;
            last.camera != request.camera
                || last.at_rest != request.at_rest
                || last.transfer_function != request.transfer_function
                || last.pool_budget_bytes != request.pool_budget_bytes
                || unfocused != request.settings
                // A new focus matters only while data is still loading frame by frame (converged passes at rest
                // serve every request anyway, and a new request would interrupt them).
                || (last.settings.focus != request.settings.focus
                    && refining
                    && (!request.at_rest || self.config.refinement == crate::render_worker::Refinement::Blended))
        });
        if changed {
            self.revision += 1;
            request.revision = self.revision;
            self.worker.request(request.clone());
            self.last_request = Some(request);
        }
    }

    fn receive(&mut self, ctx: &egui::Context) {
        for event in self.worker.events() {
            match event {
                WorkerEvent::Frame(frame) => {
                    let now = Instant::now();
                    self.frame_times.push_back((now, frame.bricks_produced));
                    while self.frame_times.front().is_some_and(|(t, _)| now.duration_since(*t) > RATE_WINDOW) {
                        self.frame_times.pop_front();
                    }
                    if frame.size[0] < self.settings.width {
                        // A moving frame: adapt the divisor to keep moving frames short.
                        if frame.frame_ms > MOVING_FRAME_MS {
                            self.moving_divisor = (self.moving_divisor * 2).min(MAX_MOVING_DIVISOR);
                        } else if frame.frame_ms < MOVING_FRAME_MS / 8.0 {
                            // Twice the edge is four times the pixels (and measured frames grow by more: a larger
                            // image also asks for finer data): grow only with room for twice that.
                            self.moving_divisor = (self.moving_divisor / 2).max(2);
                        }
                    }
                    for failure in &frame.failures {
                        // On stderr too, as `render` reports them (the first 20), since they set the exit status.
                        let before = self.failed_bricks.fetch_add(1, Ordering::Relaxed);
                        if before < MAX_REPORTED_FAILURES {
                            eprintln!("warning: {failure}; drawing its coarser ancestor instead");
                        }
                    }
                    if !frame.failures.is_empty() {
                        self.message(format!(
                            "{} brick(s) could not be produced; coarser data stands in. First: {}",
                            frame.failures.len(),
                            frame.failures[0]
                        ));
                    }
                    self.frame_log.push(FrameLog {
                        at_ms: self.opened.elapsed().as_secs_f64() * 1e3,
                        frame_ms: frame.frame_ms,
                        size: frame.size,
                        is_final: frame.is_final,
                        pending: frame.pending,
                        bricks_produced: frame.bricks_produced,
                        resident_bytes: frame.resident_bytes,
                        since_input_ms: self.last_input.map(|t| t.elapsed().as_secs_f64() * 1e3),
                    });
                    self.upload(ctx, &frame);
                    self.shown = Some(*frame);
                }
                WorkerEvent::Histogram(histogram) => self.histogram = Some(histogram),
                WorkerEvent::Error(message) => self.message(message),
                WorkerEvent::BudgetRefused { message, kept } => {
                    self.pool_budget_bytes = kept;
                    self.budget_field_mib = (kept >> 20).max(1);
                    if self.script.is_some() {
                        // A scripted session fails as a failing command does.
                        self.fail_script(ctx, format!("budget: {message}"));
                    } else {
                        self.message(message);
                    }
                }
            }
        }
        if self.worker.has_ended() && self.messages.iter().all(|m| !m.starts_with("the render thread")) {
            self.message("the render thread stopped unexpectedly; restart the viewer".into());
        }
    }

    /// `rgb` (the frame's pixels) with the colour bar and scale bar drawn over it where they are on: with the
    /// transfer function the window shows and the frame's own camera, as `render --color-bar --scale-bar` draws them.
    pub(super) fn annotated(&self, frame: &ShownFrame, rgb: Vec<u8>) -> Vec<u8> {
        if !self.annotations.any() {
            return rgb;
        }
        let tf = self.editor.transfer_function();
        let context = AnnotationContext {
            transfer_function: &tf,
            camera: &frame.camera,
            world_per_unit: 1.0,
            unit: self.config.unit.as_deref(),
        };
        annotate_rgb8(&rgb, frame.size[0], frame.size[1], self.annotations, &context)
    }

    fn upload(&mut self, ctx: &egui::Context, frame: &ShownFrame) {
        let mut rgb = frame.rgb.clone();
        if self.overlay_missing {
            for (pixel, &missing) in rgb.chunks_exact_mut(3).zip(&frame.missing) {
                if missing {
                    pixel[0] = pixel[0] / 2 + 127;
                    pixel[1] /= 2;
                    pixel[2] = pixel[2] / 2 + 127;
                }
            }
        }
        let rgb = self.annotated(frame, rgb);
        let image = ColorImage::from_rgb([frame.size[0] as usize, frame.size[1] as usize], &rgb);
        match &mut self.texture {
            Some(texture) => texture.set(image, TextureOptions::LINEAR),
            None => self.texture = Some(ctx.load_texture("voxstream-frame", image, TextureOptions::LINEAR)),
        }
    }

    fn message(&mut self, message: String) {
        if self.messages.last() != Some(&message) {
            self.messages.push(message);
        }
        if self.messages.len() > 5 {
            self.messages.remove(0);
        }
    }
}

impl eframe::App for ViewerApp {
    fn on_exit(&mut self, _gl: Option<&eframe::glow::Context>) {
        if let Some(path) = &self.config.stats_path {
            let text = format!("{:#}\n", self.stats_json());
            if let Err(message) = write_output(path, text.as_bytes()) {
                eprintln!("warning: {message}");
            }
        }
    }

    fn ui(&mut self, ui: &mut egui::Ui, _frame: &mut eframe::Frame) {
        let ctx = ui.ctx().clone();
        let overlay_before = (self.overlay_missing, self.annotations);
        self.receive(&ctx);
        self.keyboard(&ctx);
        egui::Panel::bottom("status").show(ui, |ui| self.status_line(ui));
        if !self.messages.is_empty() {
            egui::Panel::top("messages").show(ui, |ui| {
                for message in &self.messages {
                    ui.colored_label(Color32::from_rgb(255, 120, 100), message);
                }
                if ui.small_button("dismiss").clicked() {
                    self.messages.clear();
                }
            });
        }
        egui::Panel::right("controls").default_size(340.0).show(ui, |ui| {
            egui::ScrollArea::vertical().show(ui, |ui| self.controls(ui));
        });
        egui::CentralPanel::default().show(ui, |ui| self.image(ui));
        self.run_script(&ctx);
        if (self.overlay_missing, self.annotations) != overlay_before {
            // The image shown now, with or without the marks (frames may have stopped coming).
            if let Some(shown) = self.shown.take() {
                self.upload(&ctx, &shown);
                self.shown = Some(shown);
            }
        }
        self.post_request_if_changed();
        if self.moving() {
            // Ask for the full-size frame once the view rests.
            ctx.request_repaint_after(REST_AFTER);
        }
        if self.shown.as_ref().is_some_and(|s| s.size[0] < self.settings.width) && !self.moving() {
            ctx.request_repaint_after(Duration::from_millis(50));
        }
    }
}
