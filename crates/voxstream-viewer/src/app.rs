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
use std::sync::{Arc, Mutex, PoisonError};
use std::time::{Duration, Instant};

use eframe::egui::{self, Color32, ColorImage, Key, TextureHandle, TextureOptions};
use voxstream_render::{Camera, IsoSurface, RenderSettings, Shading, TransferFunction};

use crate::files::{camera_json, load_transfer_function, save_png, transfer_function_json, write_output};
use crate::histogram::SampledHistogram;
use crate::orbit::OrbitCamera;
use crate::render_worker::{RenderWorker, ShownFrame, ViewRequest, WorkerEvent};
use crate::script::{Script, ScriptCommand};
use crate::tf_editor::TransferFunctionEditor;

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
            pool_budget_bytes: config.pool_budget_bytes,
            budget_field_mib: (config.pool_budget_bytes >> 20).max(1),
            focus: [0.5, 0.5],
            show_help: false,
            messages: Vec::new(),
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

    fn keyboard(&mut self, ctx: &egui::Context) {
        if ctx.egui_wants_keyboard_input() {
            return;
        }
        let (dt, keys) = ctx.input(|i| {
            let down = |k: Key| i.key_down(k);
            let pressed = |k: Key| i.key_pressed(k);
            (
                i.stable_dt.min(0.1) as f64,
                [
                    down(Key::W) as i32 - down(Key::S) as i32,
                    down(Key::D) as i32 - down(Key::A) as i32,
                    down(Key::E) as i32 - down(Key::Q) as i32,
                    down(Key::ArrowRight) as i32 - down(Key::ArrowLeft) as i32,
                    down(Key::ArrowUp) as i32 - down(Key::ArrowDown) as i32,
                    pressed(Key::R) as i32,
                    (pressed(Key::H) || pressed(Key::F1)) as i32,
                    pressed(Key::M) as i32,
                    pressed(Key::L) as i32,
                ],
            )
        });
        let [forward, right, up, yaw, pitch, reset, help, overlay, levels] = keys;
        if levels != 0 {
            self.settings.colour_by_level = !self.settings.colour_by_level;
        }
        if forward != 0 || right != 0 || up != 0 {
            // Half the eye's distance to the target per second.
            let speed = self.orbit.distance * 0.5 * dt;
            self.orbit.fly(forward as f64 * speed, right as f64 * speed, up as f64 * speed);
            self.note_input();
        }
        if yaw != 0 || pitch != 0 {
            self.orbit.orbit(yaw as f64 * 90.0 * dt, pitch as f64 * 90.0 * dt);
            self.note_input();
        }
        if reset != 0 {
            self.reset_view();
        }
        if help != 0 {
            self.show_help = !self.show_help;
        }
        if overlay != 0 {
            self.overlay_missing = !self.overlay_missing;
        }
    }

    fn controls(&mut self, ui: &mut egui::Ui) {
        ui.heading("Transfer function");
        let histogram = self.histogram.as_ref();
        self.editor.show(ui, histogram, self.config.value_range);
        ui.horizontal(|ui| {
            egui::ComboBox::from_id_salt("presets").selected_text("presets").show_ui(ui, |ui| {
                if ui.selectable_label(false, "the source's default").clicked() {
                    self.editor.set(&self.config.transfer_function);
                }
                for (name, preset) in &self.config.presets {
                    if ui.selectable_label(false, name.as_str()).clicked() {
                        self.editor.set(preset);
                    }
                }
            });
            ui.label(format!("{} points", self.editor.points().len()));
        });
        ui.horizontal(|ui| {
            ui.add(egui::TextEdit::singleline(&mut self.tf_path).desired_width(150.0));
            if ui.button("load").on_hover_text("voxstream's JSON or a ParaView colour map").clicked() {
                let path = PathBuf::from(&self.tf_path);
                self.load_tf(&path);
            }
            if ui.button("save").on_hover_text("for voxstream render --tf").clicked() {
                let path = PathBuf::from(&self.tf_path);
                self.save_tf(&path);
            }
        });
        ui.separator();
        ui.heading("Rendering");
        let mut phong = self.settings.shading == Shading::Phong;
        if ui.checkbox(&mut phong, "Phong shading").changed() {
            self.settings.shading = if phong { Shading::Phong } else { Shading::None };
        }
        ui.add(egui::Slider::new(&mut self.settings.lod_bias, -2.0..=4.0).text("level-of-detail bias"));
        ui.add(egui::Slider::new(&mut self.settings.step_factor, 0.25..=2.0).text("step (voxels)"));
        self.isosurface_controls(ui);
        ui.checkbox(&mut self.overlay_missing, "mark pixels still missing data (M)");
        ui.checkbox(&mut self.settings.colour_by_level, "colour by the level used (L)");
        if self.settings.colour_by_level {
            ui.horizontal_wrapped(|ui| {
                ui.label("levels:");
                for level in 0..8u32 {
                    let [r, g, b] = voxstream_render::level_colour(level).map(|c| (c * 255.0) as u8);
                    ui.colored_label(Color32::from_rgb(r, g, b), format!("{level} {}", level + 8));
                }
            });
        }
        ui.horizontal(|ui| {
            ui.add(egui::DragValue::new(&mut self.budget_field_mib).range(1..=max_budget_mib()).suffix(" MiB"));
            // The field shows whole MiB; unchanged, it keeps the exact budget in use (no refill).
            let changed = self.budget_field_mib != (self.pool_budget_bytes >> 20).max(1);
            if ui.button("set budget").on_hover_text("the pools' budget: they fill again from the root").clicked()
                && changed
            {
                self.pool_budget_bytes = self.budget_field_mib << 20;
            }
        });
        ui.label(format!("render size {}×{}", self.settings.width, self.settings.height));
        ui.separator();
        ui.heading("Save");
        ui.horizontal(|ui| {
            ui.add(egui::TextEdit::singleline(&mut self.screenshot_path).desired_width(150.0));
            if ui.button("screenshot").clicked() {
                let path = PathBuf::from(&self.screenshot_path);
                if let Err(message) = self.screenshot(&path) {
                    self.message(message);
                }
            }
        });
        ui.horizontal(|ui| {
            ui.add(egui::TextEdit::singleline(&mut self.camera_path).desired_width(150.0));
            if ui.button("camera").on_hover_text("for voxstream render --camera").clicked() {
                let path = PathBuf::from(&self.camera_path);
                if let Err(message) = write_output(&path, camera_json(&self.orbit.to_camera()).as_bytes()) {
                    self.message(message);
                }
            }
        });
        ui.separator();
        ui.horizontal(|ui| {
            if ui.button("reset view (R)").clicked() {
                self.reset_view();
            }
            if ui.button("help (H)").clicked() {
                self.show_help = !self.show_help;
            }
        });
    }

    /// One exact isosurface (Knoll et al.) instead of the volume, its value on a slider over the value range.
    fn isosurface_controls(&mut self, ui: &mut egui::Ui) {
        let [lo, hi] = self.config.value_range;
        let mut on = !self.settings.surfaces.is_empty();
        let mut surface = self.settings.surfaces.first().copied().unwrap_or(IsoSurface {
            value: lo + (hi - lo) * 0.5,
            color: [0.9, 0.8, 0.7],
            opacity: 1.0,
        });
        let mut changed = ui.checkbox(&mut on, "isosurface instead of the volume").changed();
        if on {
            ui.horizontal(|ui| {
                changed |= ui.add(egui::Slider::new(&mut surface.value, lo..=hi).text("isovalue")).changed();
                changed |= ui.color_edit_button_rgb(&mut surface.color).changed();
            });
            // The transfer function's volume around the surface, composited in depth order (`render --iso --tf`).
            ui.checkbox(&mut self.settings.surfaces_in_volume, "inside the volume");
        }
        if changed {
            self.set_isosurface(on.then_some(surface));
        }
    }

    fn set_isosurface(&mut self, surface: Option<IsoSurface>) {
        match surface {
            Some(surface) => {
                if self.settings.surfaces.is_empty() {
                    self.settings.shading = Shading::Phong;
                }
                self.settings.surfaces = vec![surface];
            }
            None => {
                self.settings.surfaces.clear();
                self.settings.surfaces_in_volume = false;
                self.settings.shading = self.config.settings.shading;
            }
        }
    }

    fn status_line(&self, ui: &mut egui::Ui) {
        // Rates between the first and the last frame of the window (the first frame's bricks came before it).
        let mut parts = match (self.frame_times.front(), self.frame_times.back()) {
            (Some((first, _)), Some((last, _))) if last > first => {
                let seconds = last.duration_since(*first).as_secs_f64();
                let bricks: u64 = self.frame_times.iter().skip(1).map(|(_, b)| b).sum();
                vec![
                    format!("{:.1} frames/s", (self.frame_times.len() - 1) as f64 / seconds),
                    format!("{:.0} bricks/s", bricks as f64 / seconds),
                ]
            }
            _ => vec!["— frames/s".to_string()],
        };
        if let Some(shown) = &self.shown {
            let [resident, budget] = shown.resident_bytes;
            let mib = |b: u64| b as f64 / (1 << 20) as f64;
            parts.push(format!("resident {:.1} of {:.0} MiB", mib(resident), mib(budget)));
            parts.push(format!("{} requests pending", shown.pending));
            let state = if shown.size[0] < self.settings.width {
                format!("moving: {}×{}", shown.size[0], shown.size[1])
            } else if shown.is_final && shown.revision == self.revision {
                "final".to_string()
            } else {
                "refining".to_string()
            };
            parts.push(state);
            parts.push(format!("{:.0} ms/frame", shown.frame_ms));
        } else {
            parts.push("first frame…".into());
        }
        parts.push("H: help".into());
        ui.label(parts.join(" · "));
    }

    fn image(&mut self, ui: &mut egui::Ui) {
        let available = ui.available_rect_before_wrap();
        let aspect = self.settings.width as f32 / self.settings.height.max(1) as f32;
        let mut size = available.size();
        if size.x / size.y.max(1.0) > aspect {
            size.x = size.y * aspect;
        } else {
            size.y = size.x / aspect;
        }
        let rect = egui::Rect::from_center_size(available.center(), size);
        let response = ui.allocate_rect(rect, egui::Sense::click_and_drag());
        ui.painter().rect_filled(rect, 0.0, Color32::BLACK);
        if let Some(texture) = &self.texture {
            ui.painter().image(
                texture.id(),
                rect,
                egui::Rect::from_min_max(egui::pos2(0.0, 0.0), egui::pos2(1.0, 1.0)),
                Color32::WHITE,
            );
        }
        let delta = response.drag_delta();
        if response.dragged() && delta != egui::Vec2::ZERO {
            let panning = response.dragged_by(egui::PointerButton::Secondary)
                || response.dragged_by(egui::PointerButton::Middle)
                || ui.input(|i| i.modifiers.shift);
            if panning {
                let height = rect.height().max(1.0) as f64;
                self.orbit.pan(-delta.x as f64 / height, delta.y as f64 / height);
            } else {
                self.orbit.orbit(-delta.x as f64 * ORBIT_DEGREES_PER_POINT, delta.y as f64 * ORBIT_DEGREES_PER_POINT);
            }
            self.note_input();
        }
        // Loading goes first where the cursor is (in steps of an eighth of the image), else at the centre.
        self.focus = match response.hover_pos() {
            Some(pointer) => {
                let quantise = |v: f32| ((v * 8.0).floor().clamp(0.0, 7.0) + 0.5) / 8.0;
                [quantise((pointer.x - rect.left()) / rect.width()), quantise((pointer.y - rect.top()) / rect.height())]
            }
            None => [0.5, 0.5],
        };
        if response.hovered() {
            let scroll = ui.input(|i| i.smooth_scroll_delta.y);
            if scroll != 0.0 {
                self.orbit.zoom((-scroll as f64 * 0.002).exp());
                self.note_input();
            }
        }
        if response.double_clicked() {
            self.reset_view();
        }
        if self.show_help {
            let text = format!(
                "left drag: orbit · right/middle drag or shift+drag: pan · wheel: zoom\n\
                 W/S: fly forward/back · A/D: left/right · Q/E: down/up · arrows: orbit\n\
                 R or double-click: reset · M: mark missing data · L: colour by level · H/F1: this help\n\
                 renderer: {}",
                self.config.renderer
            );
            ui.painter().text(
                rect.left_top() + egui::vec2(8.0, 8.0),
                egui::Align2::LEFT_TOP,
                text,
                egui::FontId::proportional(14.0),
                Color32::WHITE,
            );
        }
    }

    fn load_tf(&mut self, path: &std::path::Path) {
        match load_transfer_function(path, self.config.value_range) {
            Ok(tf) => self.editor.set(&tf),
            Err(message) => self.message(message),
        }
    }

    fn save_tf(&mut self, path: &std::path::Path) {
        if let Err(message) = write_output(path, transfer_function_json(&self.editor.transfer_function()).as_bytes()) {
            self.message(message);
        }
    }

    fn screenshot(&self, path: &std::path::Path) -> Result<(), String> {
        let shown = self.shown.as_ref().ok_or("no image yet")?;
        save_png(path, shown.size, &shown.rgb)
    }

    /// Ends the scripted session with `message`: shown, left for `run_viewer` to return, and the window closed.
    fn fail_script(&mut self, ctx: &egui::Context, message: String) {
        *self.script_failure.lock().unwrap_or_else(PoisonError::into_inner) = Some(message.clone());
        self.message(message);
        self.script = None;
        ctx.send_viewport_cmd(egui::ViewportCommand::Close);
    }

    /// Runs the script's next commands; returns whether it waits (and wants a repaint soon).
    fn run_script(&mut self, ctx: &egui::Context) {
        let Some(run) = &mut self.script else { return };
        let Some((line, command)) = run.script.commands.get(run.next).cloned() else {
            self.script = None;
            return;
        };
        let name = run.script.name.clone();
        let since = run.started;
        let mut advance = true;
        let mut failure: Option<String> = None;
        match command {
            ScriptCommand::WaitFinal(timeout) => {
                let done = self.shown.as_ref().is_some_and(|s| {
                    s.is_final && s.revision == self.revision && s.size == [self.settings.width, self.settings.height]
                }) && !self.moving();
                if !done {
                    advance = false;
                    if since.elapsed() > timeout {
                        failure = Some(format!("the image was not final after {} s", timeout.as_secs_f64()));
                    }
                }
            }
            ScriptCommand::Wait(duration) => advance = since.elapsed() >= duration,
            ScriptCommand::Screenshot(path) => failure = self.screenshot(&path).err(),
            ScriptCommand::WindowScreenshot(path) => {
                // Asked once; the next frame drawn is read back and written by egui's callback, then the script
                // goes on.
                let slot = run.window_shot.get_or_insert_with(|| {
                    let slot = Arc::new(Mutex::new(None));
                    let result = slot.clone();
                    let repaint = ctx.clone();
                    ctx.request_screenshot(move |image| {
                        let rgb: Vec<u8> = image.pixels.iter().flat_map(|p| [p.r(), p.g(), p.b()]).collect();
                        let size = [image.size[0] as u32, image.size[1] as u32];
                        *result.lock().unwrap_or_else(PoisonError::into_inner) = Some(save_png(&path, size, &rgb));
                        repaint.request_repaint();
                    });
                    slot
                });
                let written = slot.lock().unwrap_or_else(PoisonError::into_inner).take();
                match written {
                    Some(result) => {
                        run.window_shot = None;
                        failure = result.err();
                    }
                    None if since.elapsed() > WINDOW_SHOT_TIMEOUT => {
                        failure = Some("the window was not read back (no frame drawn?)".into())
                    }
                    None => advance = false,
                }
            }
            ScriptCommand::Orbit(yaw, pitch) => {
                self.orbit.orbit(yaw, pitch);
                self.note_input();
            }
            ScriptCommand::Pan(right, up) => {
                self.orbit.pan(right, up);
                self.note_input();
            }
            ScriptCommand::Zoom(factor) => {
                self.orbit.zoom(factor);
                self.note_input();
            }
            ScriptCommand::Fly(forward, right, up) => {
                self.orbit.fly(forward, right, up);
                self.note_input();
            }
            ScriptCommand::Reset => self.reset_view(),
            ScriptCommand::TfPoint([value, r, g, b, alpha]) => {
                if let Some(index) = self.editor.add_point(value, alpha) {
                    self.editor.set_color(index, [r, g, b]);
                }
            }
            ScriptCommand::TfDelete(index) => {
                if !self.editor.delete_point(index) {
                    failure = Some(format!("no point {index} to delete (or it is the last one)"));
                }
            }
            ScriptCommand::LoadTf(path) => match load_transfer_function(&path, self.config.value_range) {
                Ok(tf) => self.editor.set(&tf),
                Err(message) => failure = Some(message),
            },
            ScriptCommand::SaveTf(path) => {
                failure = write_output(&path, transfer_function_json(&self.editor.transfer_function()).as_bytes()).err()
            }
            ScriptCommand::SaveCamera(path) => {
                failure = write_output(&path, camera_json(&self.orbit.to_camera()).as_bytes()).err()
            }
            ScriptCommand::Phong(on) => self.settings.shading = if on { Shading::Phong } else { Shading::None },
            ScriptCommand::LodBias(bias) => self.settings.lod_bias = bias,
            ScriptCommand::Overlay(on) => self.overlay_missing = on,
            ScriptCommand::Levels(on) => self.settings.colour_by_level = on,
            ScriptCommand::Iso(value) => {
                self.set_isosurface(value.map(|value| IsoSurface { value, color: [0.9, 0.8, 0.7], opacity: 1.0 }))
            }
            ScriptCommand::IsoInVolume(_) if self.settings.surfaces.is_empty() => {
                failure = Some("`iso-volume` draws the volume around an isosurface: give `iso VALUE` first".into())
            }
            ScriptCommand::IsoInVolume(on) => self.settings.surfaces_in_volume = on,
            ScriptCommand::Budget(mib) if mib > max_budget_mib() => {
                failure =
                    Some(format!("a budget of {mib} MiB is more than this machine's memory ({} MiB)", max_budget_mib()))
            }
            ScriptCommand::Budget(mib) => {
                self.budget_field_mib = mib;
                self.pool_budget_bytes = mib << 20;
            }
            ScriptCommand::Quit => ctx.send_viewport_cmd(egui::ViewportCommand::Close),
        }
        if let Some(message) = failure {
            self.fail_script(ctx, format!("{name} line {line}: {message}"));
            return;
        }
        if let Some(run) = &mut self.script {
            if advance {
                run.next += 1;
                run.started = Instant::now();
            }
        }
        // One command per pass: a change is posted (and its revision known) before the next command looks. A waiting
        // command looks again now and then (each new frame wakes the window too).
        ctx.request_repaint_after(if advance { Duration::ZERO } else { SCRIPT_POLL });
    }
}

impl ViewerApp {
    /// The frame log as JSON: every frame received, and the times a user feels (first image, first final image,
    /// frames while moving, from the last input to the final image).
    fn stats_json(&self) -> serde_json::Value {
        let frames: Vec<serde_json::Value> = self
            .frame_log
            .iter()
            .map(|f| {
                serde_json::json!({
                    "at_ms": f.at_ms, "frame_ms": f.frame_ms, "width": f.size[0], "height": f.size[1],
                    "final": f.is_final, "pending": f.pending, "bricks_produced": f.bricks_produced,
                    "resident_bytes": f.resident_bytes[0], "budget_bytes": f.resident_bytes[1],
                    "since_input_ms": f.since_input_ms,
                })
            })
            .collect();
        let full = [self.settings.width, self.settings.height];
        let moving: Vec<f64> = self.frame_log.iter().filter(|f| f.size != full).map(|f| f.frame_ms).collect();
        let median = |mut v: Vec<f64>| {
            v.sort_by(f64::total_cmp);
            v.get(v.len() / 2).copied()
        };
        // From the last input before each full-size final frame to that frame.
        let rest_to_final: Vec<f64> = self
            .frame_log
            .windows(2)
            .filter(|w| w[1].is_final && w[1].size == full && !(w[0].is_final && w[0].size == full))
            .filter_map(|w| w[1].since_input_ms)
            .collect();
        serde_json::json!({
            "renderer": self.config.renderer,
            "producer_failures": self.failed_bricks.load(Ordering::Relaxed),
            "render_size": full,
            "first_image_ms": self.frame_log.first().map(|f| f.at_ms),
            "first_final_ms": self.frame_log.iter().find(|f| f.is_final).map(|f| f.at_ms),
            "moving_frames": moving.len(),
            "moving_frame_ms_median": median(moving),
            "input_to_final_ms": rest_to_final,
            "frames": frames,
        })
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
        let overlay_before = self.overlay_missing;
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
        if self.overlay_missing != overlay_before {
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
