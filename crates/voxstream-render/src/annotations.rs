//! Annotations drawn over a finished image (issue 42 item 9, as ParaView's colour legend and napari's scale bar): a
//! **colour bar** of the transfer function (its colours from its first to its last point, the opacity as a white
//! curve beside them, the two ends labelled in data units) and a **scale bar** (a round length in the data's units
//! as it appears at the camera's target: for a perspective camera, nearer parts look larger and farther ones
//! smaller). Off by default; `render --color-bar --scale-bar`, `view` (the same flags, and the window's toggles),
//! Python `render(color_bar=True, scale_bar=True)`.
//!
//! Labels use the public-domain 8×8 bitmap font of `font8x8` (scaled ×2 from 512 pixels up), drawn white with a
//! black outline so they read over any background. The annotations are drawn onto a copy: the image the renderer
//! made (its statistics, the checks of empty images) is untouched.

use font8x8::{UnicodeFonts, BASIC_FONTS, LATIN_FONTS};
use glam::DVec3;

use crate::{Camera, Image, TransferFunction};

/// A number as a user would type it: `1500`, `0.25`, but `1e30` rather than thirty-one digits.
pub fn shown_number(value: f64) -> String {
    if value == 0.0 || (1e-4..1e15).contains(&value.abs()) || !value.is_finite() {
        format!("{value}")
    } else {
        format!("{value:e}")
    }
}

/// Which annotations to draw.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct Annotations {
    /// The transfer function's colour bar, at the right edge.
    pub color_bar: bool,
    /// A scale bar, at the bottom left.
    pub scale_bar: bool,
}

impl Annotations {
    /// Whether any is drawn.
    pub fn any(self) -> bool {
        self.color_bar || self.scale_bar
    }
}

/// What the annotations describe.
#[derive(Clone, Copy, Debug)]
pub struct AnnotationContext<'a> {
    /// The transfer function drawn.
    pub transfer_function: &'a TransferFunction,
    /// The camera the image was made with.
    pub camera: &'a Camera,
    /// World units per data unit along the scale bar (1 for stores, whose world is their spacing's units).
    pub world_per_unit: f64,
    /// The data's length unit as OME-Zarr names it (`millimeter`), if known.
    pub unit: Option<&'a str>,
}

/// `image` with `what` drawn over it.
pub fn annotate(image: &Image, what: Annotations, context: &AnnotationContext) -> Image {
    let mut out = image.clone();
    let scale = if image.width.min(image.height) >= 512 { 2 } else { 1 };
    if what.color_bar {
        draw_color_bar(&mut out, context.transfer_function, scale);
    }
    if what.scale_bar {
        draw_scale_bar(&mut out, context, scale);
    }
    out
}

/// [`annotate`] over 8-bit RGB pixels (`width × height`, top row first), as a window shows them.
pub fn annotate_rgb8(rgb: &[u8], width: u32, height: u32, what: Annotations, context: &AnnotationContext) -> Vec<u8> {
    let pixels =
        rgb.chunks_exact(3).map(|p| [0, 1, 2].map(|c| f32::from(p[c]) / 255.0)).map(|[r, g, b]| [r, g, b, 1.0]);
    let image = Image { width, height, pixels: pixels.collect() };
    annotate(&image, what, context).to_rgb8()
}

/// A short unit label: `mm` for `millimeter`, `µm` for `micrometer`; other names as they are; `units` when unknown.
pub fn unit_label(unit: Option<&str>) -> &str {
    match unit {
        Some("meter") => "m",
        Some("centimeter") => "cm",
        Some("millimeter") => "mm",
        Some("micrometer") => "µm",
        Some("nanometer") => "nm",
        Some("angstrom") => "Å",
        Some(other) => other,
        None => "units",
    }
}

/// The largest of 1, 2 and 5 times a power of ten not above `length`.
pub fn round_length(length: f64) -> f64 {
    if !(length.is_finite() && length > 0.0) {
        return 1.0;
    }
    let power = 10f64.powf(length.log10().floor());
    [5.0, 2.0, 1.0].into_iter().map(|m| m * power).find(|&l| l <= length * (1.0 + 1e-12)).unwrap_or(power)
}

fn set(image: &mut Image, x: i64, y: i64, color: [f32; 3]) {
    if x >= 0 && y >= 0 && (x as u32) < image.width && (y as u32) < image.height {
        let p = &mut image.pixels[y as usize * image.width as usize + x as usize];
        *p = [color[0], color[1], color[2], 1.0];
    }
}

fn fill(image: &mut Image, x0: i64, y0: i64, w: i64, h: i64, color: [f32; 3]) {
    for y in y0..y0 + h {
        for x in x0..x0 + w {
            set(image, x, y, color);
        }
    }
}

/// Pixels a label takes across at `scale`.
fn text_width(text: &str, scale: i64) -> i64 {
    text.chars().count() as i64 * 8 * scale
}

/// Draws `text` with its top left at (x, y): white glyphs in a black outline.
fn draw_text(image: &mut Image, x: i64, y: i64, text: &str, scale: i64) {
    let glyphs: Vec<[u8; 8]> =
        text.chars().map(|c| BASIC_FONTS.get(c).or_else(|| LATIN_FONTS.get(c)).unwrap_or([0; 8])).collect();
    let lit = |gx: i64, gy: i64| -> bool {
        let (cell, col) = (gx.div_euclid(8 * scale), gx.rem_euclid(8 * scale) / scale);
        let row = gy.div_euclid(scale);
        if gy < 0 || row >= 8 || cell < 0 || cell as usize >= glyphs.len() {
            return false;
        }
        glyphs[cell as usize][row as usize] & (1 << col) != 0
    };
    let (w, h) = (text_width(text, scale), 8 * scale);
    for gy in -1..=h {
        for gx in -1..=w {
            if lit(gx, gy) {
                set(image, x + gx, y + gy, [1.0; 3]);
            } else if (-1..=1).any(|dy| (-1..=1).any(|dx| lit(gx + dx, gy + dy))) {
                set(image, x + gx, y + gy, [0.0; 3]);
            }
        }
    }
}

/// The colour bar: a strip of the transfer function's colours from its first point's value (bottom) to its last's
/// (top), its opacity relative to its largest as a white curve in a dark strip beside it, the ends labelled.
fn draw_color_bar(image: &mut Image, tf: &TransferFunction, scale: i64) {
    let (width, height) = (i64::from(image.width), i64::from(image.height));
    let (lo, hi) = match (tf.points.first(), tf.points.last()) {
        (Some(first), Some(last)) if last[0] > first[0] => (first[0], last[0]),
        (Some(only), _) => (only[0] - 0.5, only[0] + 0.5),
        _ => return,
    };
    let (lo_label, hi_label) = (shown_number(lo), shown_number(hi));
    let label_width = text_width(&lo_label, scale).max(text_width(&hi_label, scale));
    let strip = 10 * scale;
    let bar_height = (height * 3 / 5).max(16);
    let right = width - 6 * scale;
    let x0 = right - 2 * strip - 2;
    let y0 = (height - bar_height) / 2;
    let max_alpha = tf.points.iter().map(|p| p[4]).fold(0.0, f64::max).max(1e-12);
    // A frame.
    fill(image, x0 - 1, y0 - 1, 2 * strip + 4, bar_height + 2, [0.5; 3]);
    for row in 0..bar_height {
        let value = hi - (hi - lo) * row as f64 / (bar_height - 1).max(1) as f64;
        let [r, g, b, a] = tf.evaluate(value);
        let y = y0 + row;
        fill(image, x0, y, strip, 1, [r as f32, g as f32, b as f32]);
        fill(image, x0 + strip + 1, y, strip + 1, 1, [0.08; 3]);
        let at = x0 + strip + 1 + ((a / max_alpha).clamp(0.0, 1.0) * strip as f64).round() as i64;
        set(image, at.min(x0 + 2 * strip + 1), y, [1.0; 3]);
    }
    let label_x = (x0 - 4 * scale - label_width).max(0);
    draw_text(image, label_x, y0, &hi_label, scale);
    draw_text(image, label_x, y0 + bar_height - 8 * scale, &lo_label, scale);
}

/// The scale bar: a round length at the camera's target, about a fifth of the image wide, labelled.
fn draw_scale_bar(image: &mut Image, context: &AnnotationContext, scale: i64) {
    let camera = context.camera;
    let (width, height) = (f64::from(image.width), f64::from(image.height));
    let distance = (DVec3::from(camera.target) - DVec3::from(camera.eye)).length();
    // World units a pixel spans at the target's distance (the vertical field of view spans the image's height).
    let world_per_pixel = 2.0 * distance * (camera.fov.to_radians() / 2.0).tan() / height;
    let units_per_pixel = world_per_pixel / context.world_per_unit.max(f64::MIN_POSITIVE);
    if !(units_per_pixel.is_finite() && units_per_pixel > 0.0) {
        return;
    }
    let length = round_length(units_per_pixel * width / 5.0);
    let pixels = (length / units_per_pixel).round() as i64;
    let label = format!("{} {}", shown_number(length), unit_label(context.unit));
    let (x0, y0) = (8 * scale, height as i64 - 8 * scale - 4 * scale);
    fill(image, x0 - 1, y0 - 1, pixels + 2, 4 * scale + 2, [0.0; 3]);
    fill(image, x0, y0, pixels, 4 * scale, [1.0; 3]);
    draw_text(image, x0, y0 - 12 * scale, &label, scale);
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn lengths_round_down_to_one_two_or_five_and_units_shorten() {
        assert_eq!(round_length(7.3), 5.0);
        assert_eq!(round_length(19.9), 10.0);
        assert_eq!(round_length(0.25), 0.2);
        assert_eq!(round_length(2.0), 2.0);
        assert_eq!(round_length(f64::NAN), 1.0);
        assert_eq!(unit_label(Some("micrometer")), "µm");
        assert_eq!(unit_label(Some("parsec")), "parsec");
        assert_eq!(unit_label(None), "units");
    }

    #[test]
    fn the_scale_bar_spans_its_length_at_the_target() {
        // A camera 10 units from its target with a 90° field of view: the 100-pixel-high image spans 20 units, so a
        // pixel is 0.2 units; a fifth of the 100-pixel width is 4 units, rounded down to 2: 10 pixels.
        let camera = Camera { eye: [0.0, 0.0, 10.0], target: [0.0; 3], up: [0.0, 1.0, 0.0], fov: 90.0 };
        let tf = TransferFunction::new(vec![[0.0, 0.0, 0.0, 0.0, 0.0], [1.0, 1.0, 0.0, 0.0, 1.0]], None).unwrap();
        let context = AnnotationContext {
            transfer_function: &tf,
            camera: &camera,
            world_per_unit: 1.0,
            unit: Some("millimeter"),
        };
        let image = Image::new(100, 100);
        let drawn = annotate(&image, Annotations { scale_bar: true, color_bar: false }, &context);
        // The bar's row: white from x = 8 for 10 pixels, black borders either side.
        let row = 100 - 8 - 4 + 1;
        let white: Vec<usize> = (0..100).filter(|&x| drawn.pixels[row * 100 + x] == [1.0, 1.0, 1.0, 1.0]).collect();
        assert_eq!(white, (8..18).collect::<Vec<_>>());
        assert_eq!(image.pixels, Image::new(100, 100).pixels, "the image given is untouched");
        // Half a world unit per data unit: a pixel is 0.4 units, a fifth of the width 8, rounded down to 5: 12.5
        // pixels, drawn 13.
        let context = AnnotationContext { world_per_unit: 0.5, ..context };
        let drawn = annotate(&image, Annotations { scale_bar: true, color_bar: false }, &context);
        let white = (0..100).filter(|&x| drawn.pixels[row * 100 + x] == [1.0, 1.0, 1.0, 1.0]).count();
        assert_eq!(white, 13);
    }

    #[test]
    fn the_colour_bar_shows_the_transfer_functions_colours_from_bottom_to_top() {
        let camera = Camera { eye: [0.0, 0.0, 10.0], target: [0.0; 3], up: [0.0, 1.0, 0.0], fov: 30.0 };
        let tf = TransferFunction::new(vec![[0.0, 0.0, 0.0, 1.0, 0.1], [100.0, 1.0, 0.0, 0.0, 0.5]], None).unwrap();
        let context = AnnotationContext { transfer_function: &tf, camera: &camera, world_per_unit: 1.0, unit: None };
        let drawn = annotate(&Image::new(200, 200), Annotations { color_bar: true, scale_bar: false }, &context);
        // The strip's left column: blue at the bottom, red at the top.
        let x0 = 200 - 6 - 20 - 2;
        let (y0, y1) = ((200 - 120) / 2, (200 - 120) / 2 + 119);
        let top = drawn.pixels[y0 * 200 + x0];
        let bottom = drawn.pixels[y1 * 200 + x0];
        assert_eq!((top[0], top[2]), (1.0, 0.0), "{top:?}");
        assert_eq!((bottom[0], bottom[2]), (0.0, 1.0), "{bottom:?}");
        // The labels are drawn (white pixels left of the strip).
        let lit = (0..200 * 200).filter(|&i| i % 200 < x0 - 4 && drawn.pixels[i][..3] == [1.0, 1.0, 1.0]).count();
        assert!(lit > 20, "{lit}");
    }
}
