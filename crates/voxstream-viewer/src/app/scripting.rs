//! The scripted session (`--script`): commands run one per window pass, files the viewer reads and writes
//! (transfer functions, screenshots), and the frame log written as `--stats` JSON.

use std::sync::atomic::Ordering;
use std::sync::{Arc, Mutex, PoisonError};
use std::time::{Duration, Instant};

use eframe::egui;
use voxstream_render::{IsoSurface, Shading};

use super::{max_budget_mib, ViewerApp, SCRIPT_POLL, WINDOW_SHOT_TIMEOUT};
use crate::files::{camera_json, load_transfer_function, save_png, transfer_function_json, write_output};
use crate::script::ScriptCommand;

impl ViewerApp {
    pub(super) fn load_tf(&mut self, path: &std::path::Path) {
        match load_transfer_function(path, self.config.value_range) {
            Ok(tf) => self.editor.set(&tf),
            Err(message) => self.message(message),
        }
    }

    pub(super) fn save_tf(&mut self, path: &std::path::Path) {
        if let Err(message) = write_output(path, transfer_function_json(&self.editor.transfer_function()).as_bytes()) {
            self.message(message);
        }
    }

    pub(super) fn screenshot(&self, path: &std::path::Path) -> Result<(), String> {
        let shown = self.shown.as_ref().ok_or("no image yet")?;
        save_png(path, shown.size, &self.annotated(shown, shown.rgb.clone()))
    }

    /// Ends the scripted session with `message`: shown, left for `run_viewer` to return, and the window closed.
    pub(super) fn fail_script(&mut self, ctx: &egui::Context, message: String) {
        *self.script_failure.lock().unwrap_or_else(PoisonError::into_inner) = Some(message.clone());
        self.message(message);
        self.script = None;
        ctx.send_viewport_cmd(egui::ViewportCommand::Close);
    }

    /// Runs the script's next commands; returns whether it waits (and wants a repaint soon).
    pub(super) fn run_script(&mut self, ctx: &egui::Context) {
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

    /// The frame log as JSON: every frame received, and the times a user feels (first image, first final image,
    /// frames while moving, from the last input to the final image).
    pub(super) fn stats_json(&self) -> serde_json::Value {
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
            "renderer_warning": self.config.renderer_warning,
            "producer_failures": self.failed_bricks.load(Ordering::Relaxed),
            "status_line": self.status_text(),
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
