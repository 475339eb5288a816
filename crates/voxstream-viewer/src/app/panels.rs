//! The window's panels: the controls (transfer function, shading, isosurfaces, budget), the status line, the image
//! with its pointer handling (orbit, pan, zoom), and the keyboard.

use std::path::PathBuf;

use eframe::egui::{self, Color32, Key};
use voxstream_render::{IsoSurface, Shading};

use super::{max_budget_mib, ViewerApp, ORBIT_DEGREES_PER_POINT};
use crate::files::{camera_json, write_output};

/// The keys that may close the window, and what else is open.
#[derive(Clone, Copy, Debug, Default)]
pub(super) struct DismissKeys {
    /// `Esc` was pressed.
    pub escape: bool,
    /// `Ctrl+Q` (`Cmd+Q` on macOS) was pressed.
    pub command_q: bool,
    /// A text field has the keyboard.
    pub typing: bool,
    /// The help overlay is shown.
    pub help_shown: bool,
    /// A popup (the presets' list) is open.
    pub popup_open: bool,
}

/// What `Esc` or `Ctrl+Q` does.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub(super) enum Dismiss {
    Nothing,
    HideHelp,
    CloseWindow,
}

/// `Ctrl+Q` closes the window whatever has the keyboard. `Esc` closes what is open first (a text field's focus or a
/// popup, which egui closes itself, or the help overlay), and the window when nothing is.
pub(super) fn dismiss(keys: DismissKeys) -> Dismiss {
    if keys.command_q {
        Dismiss::CloseWindow
    } else if !keys.escape || keys.typing || keys.popup_open {
        Dismiss::Nothing
    } else if keys.help_shown {
        Dismiss::HideHelp
    } else {
        Dismiss::CloseWindow
    }
}

impl ViewerApp {
    pub(super) fn keyboard(&mut self, ctx: &egui::Context) {
        let typing = ctx.egui_wants_keyboard_input();
        let (escape, command_q) =
            ctx.input(|i| (i.key_pressed(Key::Escape), i.modifiers.command && i.key_pressed(Key::Q)));
        let popup_open = egui::Popup::is_any_open(ctx);
        let keys = DismissKeys { escape, command_q, typing, help_shown: self.show_help, popup_open };
        match dismiss(keys) {
            Dismiss::Nothing => {}
            Dismiss::HideHelp => self.show_help = false,
            // As the window's close button: `on_exit` writes `--stats`.
            Dismiss::CloseWindow => {
                ctx.send_viewport_cmd(egui::ViewportCommand::Close);
                return;
            }
        }
        if typing {
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

    pub(super) fn controls(&mut self, ui: &mut egui::Ui) {
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
        ui.checkbox(&mut self.annotations.color_bar, "colour bar of the transfer function");
        ui.checkbox(&mut self.annotations.scale_bar, "scale bar");
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
    pub(super) fn isosurface_controls(&mut self, ui: &mut egui::Ui) {
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

    pub(super) fn set_isosurface(&mut self, surface: Option<IsoSurface>) {
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

    pub(super) fn status_line(&self, ui: &mut egui::Ui) {
        ui.label(self.status_text());
    }

    /// The status line's text: rates, memory, requests, the frame's state and time, and bricks that failed.
    pub(super) fn status_text(&self) -> String {
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
            if let Some(host_caches) = &self.config.host_caches {
                parts.push(host_caches());
            }
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
        // Bricks that could not be produced (a damaged store, a server that failed them): their ancestors stand in,
        // and the viewer will exit 3 as `render` does.
        let failed = self.failed_bricks.load(std::sync::atomic::Ordering::Relaxed);
        if failed > 0 {
            parts.push(format!("{failed} brick{} failed (coarser data stands in)", if failed == 1 { "" } else { "s" }));
        }
        parts.push("H: help".into());
        parts.join(" · ")
    }

    pub(super) fn image(&mut self, ui: &mut egui::Ui) {
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
                 Esc: hide this help, then close · Ctrl+Q: close (--stats is written)\n\
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
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn escape_closes_the_window_once_nothing_else_is_open_and_ctrl_q_always() {
        let escape = DismissKeys { escape: true, ..DismissKeys::default() };
        assert_eq!(dismiss(escape), Dismiss::CloseWindow);
        assert_eq!(dismiss(DismissKeys { help_shown: true, ..escape }), Dismiss::HideHelp);
        assert_eq!(dismiss(DismissKeys { typing: true, ..escape }), Dismiss::Nothing, "Esc leaves the text field");
        assert_eq!(dismiss(DismissKeys { popup_open: true, ..escape }), Dismiss::Nothing, "Esc closes the popup");
        let quit = DismissKeys { command_q: true, typing: true, help_shown: true, popup_open: true, escape: false };
        assert_eq!(dismiss(quit), Dismiss::CloseWindow);
        assert_eq!(dismiss(DismissKeys::default()), Dismiss::Nothing);
        assert_eq!(dismiss(DismissKeys { help_shown: true, ..DismissKeys::default() }), Dismiss::Nothing);
    }
}
