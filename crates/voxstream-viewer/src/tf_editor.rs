//! The transfer-function editor: control points over the source's value histogram.
//!
//! The model ([`TransferFunctionEditor`]: add, move, recolour, delete points, always a valid
//! [`TransferFunction`]) is separate from its drawing ([`TransferFunctionEditor::show`]), so the window and
//! scripted sessions edit the same way, and the model is tested without a window.
//!
//! In the plot ([`Plot`]), x is the data value over the source's value range (labelled in data units below it:
//! [`value_axis`]), y the opacity on a square-root axis (the opacities that matter in translucent volumes are small).
//! Drag a point to move it (the point under the press, however far the pointer went before egui saw a drag),
//! double-click empty space to add one (its colour interpolated), right-click a point to delete it, click a point to
//! pick its colour below.

use eframe::egui::{self, Align2, Color32, Pos2, Rect, Sense, Stroke, Vec2};
use voxstream_render::TransferFunction;

use crate::histogram::SampledHistogram;
use crate::value_axis;

/// Pixels within which a click picks a point.
pub const PICK_RADIUS: f32 = 8.0;

/// Height of the plot, points.
const PLOT_HEIGHT: f32 = 150.0;

/// Height of the value axis under it, points.
const AXIS_HEIGHT: f32 = 16.0;

/// Editable control points, kept valid: values strictly increasing, colours and opacities in `[0, 1]`.
#[derive(Clone, Debug, PartialEq)]
pub struct TransferFunctionEditor {
    points: Vec<[f64; 5]>,
    unit_distance: Option<f64>,
    selected: Option<usize>,
    dragged: Option<usize>,
}

impl TransferFunctionEditor {
    /// An editor holding `transfer_function`.
    pub fn new(transfer_function: &TransferFunction) -> TransferFunctionEditor {
        TransferFunctionEditor {
            points: transfer_function.points.clone(),
            unit_distance: transfer_function.unit_distance,
            selected: None,
            dragged: None,
        }
    }

    /// Replaces the whole function (a preset, a loaded file).
    pub fn set(&mut self, transfer_function: &TransferFunction) {
        *self = TransferFunctionEditor::new(transfer_function);
    }

    /// The function edited so far.
    pub fn transfer_function(&self) -> TransferFunction {
        TransferFunction { points: self.points.clone(), unit_distance: self.unit_distance }
    }

    /// The control points.
    pub fn points(&self) -> &[[f64; 5]] {
        &self.points
    }

    /// The point whose colour the colour button edits.
    pub fn selected(&self) -> Option<usize> {
        self.selected
    }

    /// Adds a point at `value` with opacity `alpha` and the colour the function has there; a point already at
    /// `value` is moved to `alpha` instead. Returns its index.
    pub fn add_point(&mut self, value: f64, alpha: f64) -> Option<usize> {
        if !value.is_finite() || !alpha.is_finite() {
            return None;
        }
        let alpha = alpha.clamp(0.0, 1.0);
        if let Some(existing) = self.points.iter().position(|p| p[0] == value) {
            self.points[existing][4] = alpha;
            return Some(existing);
        }
        let [r, g, b, _] = self.transfer_function().evaluate(value);
        let index = self.points.partition_point(|p| p[0] < value);
        self.points.insert(index, [value, r, g, b, alpha]);
        self.selected = Some(index);
        Some(index)
    }

    /// Moves point `index` to `value` (kept strictly between its neighbours) and opacity `alpha`.
    pub fn move_point(&mut self, index: usize, value: f64, alpha: f64) {
        if index >= self.points.len() || !value.is_finite() || !alpha.is_finite() {
            return;
        }
        let below = index.checked_sub(1).map(|i| self.points[i][0]);
        let above = self.points.get(index + 1).map(|p| p[0]);
        let mut value = value;
        if let Some(below) = below {
            value = value.max(next_above(below));
        }
        if let Some(above) = above {
            value = value.min(next_below(above));
        }
        if below.is_some_and(|b| value <= b) || above.is_some_and(|a| value >= a) {
            return;
        }
        self.points[index][0] = value;
        self.points[index][4] = alpha.clamp(0.0, 1.0);
    }

    /// Sets the colour of point `index`.
    pub fn set_color(&mut self, index: usize, rgb: [f64; 3]) {
        if let Some(point) = self.points.get_mut(index) {
            for (channel, value) in point[1..4].iter_mut().zip(rgb) {
                if value.is_finite() {
                    *channel = value.clamp(0.0, 1.0);
                }
            }
        }
    }

    /// Deletes point `index`; the last point is kept. Returns whether it was deleted.
    pub fn delete_point(&mut self, index: usize) -> bool {
        if self.points.len() <= 1 || index >= self.points.len() {
            return false;
        }
        self.points.remove(index);
        self.selected = None;
        self.dragged = None;
        true
    }

    /// Draws the editor over `histogram` (when sampled) and handles the pointer; returns whether the function
    /// changed. `value_range` is the source's.
    pub fn show(&mut self, ui: &mut egui::Ui, histogram: Option<&SampledHistogram>, value_range: [f64; 2]) -> bool {
        let before = self.points.clone();
        let width = ui.available_width().max(120.0);
        let (response, painter) =
            ui.allocate_painter(Vec2::new(width, PLOT_HEIGHT + AXIS_HEIGHT), Sense::click_and_drag());
        let plot_area = Rect::from_min_max(
            response.rect.min,
            Pos2::new(response.rect.right(), response.rect.bottom() - AXIS_HEIGHT),
        );
        let lo = value_range[0].min(self.points[0][0]);
        let hi = value_range[1].max(self.points[self.points.len() - 1][0]);
        let plot = Plot::new(plot_area.shrink(6.0), lo, hi);
        let rect = plot.rect;
        painter.rect_filled(plot_area, 2.0, Color32::from_gray(24));
        if let Some(histogram) = histogram {
            draw_histogram(&painter, &plot, histogram);
        }
        draw_value_axis(&painter, &plot, ui.visuals().weak_text_color());
        // The colour strip along the bottom, and the opacity curve.
        let strip = 64;
        let transfer_function = self.transfer_function();
        for i in 0..strip {
            let value = plot.lo + plot.span * (i as f64 + 0.5) / strip as f64;
            let [r, g, b, _] = transfer_function.evaluate(value);
            let x0 = rect.left() + rect.width() * i as f32 / strip as f32;
            let x1 = rect.left() + rect.width() * (i + 1) as f32 / strip as f32;
            painter.rect_filled(
                Rect::from_min_max(Pos2::new(x0, rect.bottom() - 6.0), Pos2::new(x1, rect.bottom())),
                0.0,
                color(r, g, b),
            );
        }
        let mut curve = vec![plot.to_screen(lo, self.points[0][4])];
        curve.extend(self.points.iter().map(|p| plot.to_screen(p[0], p[4])));
        curve.push(plot.to_screen(hi, self.points[self.points.len() - 1][4]));
        painter.line(curve, Stroke::new(1.5, Color32::from_gray(220)));
        for (index, p) in self.points.iter().enumerate() {
            let centre = plot.to_screen(p[0], p[4]);
            painter.circle_filled(centre, 5.0, color(p[1], p[2], p[3]));
            let ring = if self.selected == Some(index) { Color32::YELLOW } else { Color32::WHITE };
            painter.circle_stroke(centre, 5.0, Stroke::new(1.5, ring));
        }
        if let Some(pointer) = response.interact_pointer_pos() {
            if response.drag_started() {
                // egui starts a drag once the pointer has moved some pixels (or further, between two slow frames):
                // the point is the one under the press, not under the pointer now.
                let press = ui.input(|i| i.pointer.press_origin());
                self.dragged = plot.pick_for_drag(&self.points, press, pointer);
                if self.dragged.is_some() {
                    self.selected = self.dragged;
                }
            }
            if response.clicked() {
                if let Some(index) = plot.pick(&self.points, pointer) {
                    self.selected = Some(index);
                }
            }
            if response.dragged() {
                if let Some(index) = self.dragged {
                    let (value, alpha) = plot.from_screen(pointer);
                    self.move_point(index, value, alpha);
                }
            }
            if response.double_clicked() && plot.pick(&self.points, pointer).is_none() {
                let (value, alpha) = plot.from_screen(pointer);
                self.add_point(value, alpha);
            }
            if response.secondary_clicked() {
                if let Some(index) = plot.pick(&self.points, pointer) {
                    self.delete_point(index);
                }
            }
        }
        if response.drag_stopped() {
            self.dragged = None;
        }
        response.on_hover_text("drag: move a point · double-click: add · right-click: delete · click: pick its colour");
        if let Some(index) = self.selected.filter(|&i| i < self.points.len()) {
            ui.horizontal(|ui| {
                let p = self.points[index];
                let mut rgb = [p[1] as f32, p[2] as f32, p[3] as f32];
                ui.label(format!("point {index}: value {:.4}, opacity {:.3}", p[0], p[4]));
                if ui.color_edit_button_rgb(&mut rgb).changed() {
                    self.set_color(index, rgb.map(f64::from));
                }
            });
        }
        self.points != before
    }
}

/// Where values and opacities are in the plot: x the value over `lo..lo + span`, y the opacity on a square-root
/// axis.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Plot {
    /// The plotting area (points).
    pub rect: Rect,
    /// The value at the left edge.
    pub lo: f64,
    /// The values across the plot (positive).
    pub span: f64,
}

impl Plot {
    /// A plot of values `lo..=hi` (a span of 1 when they are equal) in `rect`.
    pub fn new(rect: Rect, lo: f64, hi: f64) -> Plot {
        Plot { rect, lo, span: if hi > lo { hi - lo } else { 1.0 } }
    }

    /// The point of `value` at opacity `alpha`.
    pub fn to_screen(&self, value: f64, alpha: f64) -> Pos2 {
        let rect = self.rect;
        Pos2::new(
            rect.left() + ((value - self.lo) / self.span) as f32 * rect.width(),
            rect.bottom() - (alpha.max(0.0).sqrt() as f32) * rect.height(),
        )
    }

    /// The value and opacity at point `p` (the opacity clamped to `[0, 1]`).
    pub fn from_screen(&self, p: Pos2) -> (f64, f64) {
        let rect = self.rect;
        let value = self.lo + ((p.x - rect.left()) / rect.width()) as f64 * self.span;
        let height = ((rect.bottom() - p.y) / rect.height()).clamp(0.0, 1.0) as f64;
        (value, height * height)
    }

    /// The point a drag takes when it starts: the one under `press`, where the button went down (egui's
    /// `press_origin`), not the one under the pointer now, which a drag recognised late has left behind; `pointer`
    /// where no press is known.
    pub fn pick_for_drag(&self, points: &[[f64; 5]], press: Option<Pos2>, pointer: Pos2) -> Option<usize> {
        self.pick(points, press.unwrap_or(pointer))
    }

    /// The control point within [`PICK_RADIUS`] of `at` (the nearest), if any.
    pub fn pick(&self, points: &[[f64; 5]], at: Pos2) -> Option<usize> {
        points
            .iter()
            .enumerate()
            .map(|(i, p)| (i, self.to_screen(p[0], p[4]).distance(at)))
            .filter(|&(_, d)| d <= PICK_RADIUS)
            .min_by(|a, b| a.1.total_cmp(&b.1))
            .map(|(i, _)| i)
    }
}

fn draw_histogram(painter: &egui::Painter, plot: &Plot, histogram: &SampledHistogram) {
    let (rect, lo, span) = (plot.rect, plot.lo, plot.span);
    let max = histogram.max_count();
    if max == 0 {
        return;
    }
    let bins = histogram.counts.len();
    let [h_lo, h_hi] = histogram.value_range;
    let log_max = (max as f64).ln_1p();
    for (i, &count) in histogram.counts.iter().enumerate() {
        if count == 0 {
            continue;
        }
        let v0 = h_lo + (h_hi - h_lo) * i as f64 / bins as f64;
        let v1 = h_lo + (h_hi - h_lo) * (i + 1) as f64 / bins as f64;
        let x0 = rect.left() + ((v0 - lo) / span) as f32 * rect.width();
        let x1 = rect.left() + ((v1 - lo) / span) as f32 * rect.width();
        // Log counts: the background voxels would flatten everything else.
        let height = ((count as f64).ln_1p() / log_max) as f32 * rect.height();
        painter.rect_filled(
            Rect::from_min_max(Pos2::new(x0, rect.bottom() - height), Pos2::new(x1.max(x0 + 1.0), rect.bottom())),
            0.0,
            Color32::from_gray(70),
        );
    }
}

/// Tick marks and labels in data units under the plot ([`value_axis::value_ticks`]).
fn draw_value_axis(painter: &egui::Painter, plot: &Plot, text: Color32) {
    let rect = plot.rect;
    let font = egui::FontId::proportional(11.0);
    let y = rect.bottom() + 6.0;
    for tick in value_axis::value_ticks(plot.lo, plot.lo + plot.span, rect.width()) {
        let x = rect.left() + tick.position * rect.width();
        painter.line_segment([Pos2::new(x, y - 3.0), Pos2::new(x, y + 1.0)], Stroke::new(1.0, text));
        let anchor = match (tick.is_end, tick.position < 0.5) {
            (true, true) => Align2::LEFT_TOP,
            (true, false) => Align2::RIGHT_TOP,
            (false, _) => Align2::CENTER_TOP,
        };
        painter.text(Pos2::new(x, y + 1.0), anchor, tick.label, font.clone(), text);
    }
}

fn color(r: f64, g: f64, b: f64) -> Color32 {
    let byte = |v: f64| (v.clamp(0.0, 1.0) * 255.0).round() as u8;
    Color32::from_rgb(byte(r), byte(g), byte(b))
}

fn next_above(value: f64) -> f64 {
    let step = (value.abs() * 1e-9).max(1e-12);
    value + step
}

fn next_below(value: f64) -> f64 {
    let step = (value.abs() * 1e-9).max(1e-12);
    value - step
}

#[cfg(test)]
mod tests {
    use super::*;

    fn ramp() -> TransferFunction {
        TransferFunction::new(vec![[0.0, 0.0, 0.0, 0.0, 0.0], [1.0, 1.0, 0.5, 0.0, 0.8]], None).unwrap()
    }

    #[test]
    fn an_added_point_takes_the_interpolated_colour_and_keeps_the_order() {
        let mut editor = TransferFunctionEditor::new(&ramp());
        let index = editor.add_point(0.5, 0.3).unwrap();
        assert_eq!(index, 1);
        assert_eq!(editor.points()[1], [0.5, 0.5, 0.25, 0.0, 0.3]);
        assert!(TransferFunction::new(editor.points().to_vec(), None).is_ok());
        assert_eq!(editor.add_point(f64::NAN, 0.2), None);
        assert_eq!(editor.add_point(0.5, 7.0), Some(1), "a point at the same value is moved, opacity clamped");
        assert_eq!(editor.points()[1][4], 1.0);
    }

    #[test]
    fn a_moved_point_never_passes_its_neighbours() {
        let mut editor = TransferFunctionEditor::new(&ramp());
        editor.add_point(0.5, 0.3);
        editor.move_point(1, 5.0, 0.4);
        let points = editor.points();
        assert!(points[1][0] < points[2][0] && points[1][0] > 0.99, "clamped below the next point: {points:?}");
        editor.move_point(1, -3.0, -1.0);
        let points = editor.points();
        assert!(points[1][0] > points[0][0] && points[1][0] < 0.01);
        assert_eq!(points[1][4], 0.0);
        assert!(TransferFunction::new(points.to_vec(), None).is_ok(), "still strictly increasing");
    }

    #[test]
    fn a_drag_takes_the_point_under_the_press_however_far_it_moved_first() {
        let plot = Plot::new(Rect::from_min_size(Pos2::new(10.0, 20.0), Vec2::new(200.0, 100.0)), 0.0, 1.0);
        let points = [[0.0, 0.0, 0.0, 0.0, 0.0], [0.5, 1.0, 1.0, 1.0, 0.25], [1.0, 1.0, 1.0, 1.0, 1.0]];
        // Point 1 is at x = 10 + 0.5 × 200, y = 120 − √0.25 × 100.
        let centre = plot.to_screen(0.5, 0.25);
        assert_eq!(centre, Pos2::new(110.0, 70.0));
        // Pressed 3 px off the point; the drag was recognised 30 px later.
        let press = centre + Vec2::new(3.0, -2.0);
        let pointer = press + Vec2::new(30.0, 12.0);
        assert_eq!(plot.pick(&points, pointer), None, "nothing under the pointer now");
        assert_eq!(plot.pick_for_drag(&points, Some(press), pointer), Some(1));
        // No press known (a touch that began elsewhere): the pointer decides.
        assert_eq!(plot.pick_for_drag(&points, None, centre), Some(1));
        assert_eq!(plot.pick_for_drag(&points, Some(centre + Vec2::new(PICK_RADIUS + 1.0, 0.0)), centre), None);
        // Of two points within reach, the nearer.
        let close = [[0.5, 0.0, 0.0, 0.0, 0.25], [0.52, 0.0, 0.0, 0.0, 0.25]];
        assert_eq!(plot.pick(&close, plot.to_screen(0.52, 0.25) + Vec2::new(-1.0, 0.0)), Some(1));
        // And back: the press's value and opacity.
        let (value, alpha) = plot.from_screen(centre);
        assert!((value - 0.5).abs() < 1e-6 && (alpha - 0.25).abs() < 1e-6);
    }

    #[test]
    fn deleting_keeps_one_point_and_colours_are_clamped() {
        let mut editor = TransferFunctionEditor::new(&ramp());
        editor.set_color(0, [2.0, -1.0, f64::NAN]);
        assert_eq!(&editor.points()[0][1..4], &[1.0, 0.0, 0.0]);
        assert!(editor.delete_point(1));
        assert!(!editor.delete_point(0), "the last point stays");
        assert!(!editor.delete_point(9));
        assert_eq!(editor.transfer_function().points.len(), 1);
    }
}
