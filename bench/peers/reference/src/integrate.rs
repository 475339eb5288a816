//! Ray integration, brute force: emission-absorption volume rendering with midpoint samples at a fixed step,
//! and first-hit isosurfaces found by a fixed-step scan plus bisection; optional two-sided Phong shading from
//! the analytic gradient. Blocks of 8^3 cells that cannot contribute are skipped without fetching samples, in a
//! way that leaves every result bit-for-bit unchanged. Rows are rendered in parallel with rayon.

use anyhow::{Context, Result};
use rayon::prelude::*;

use crate::camera::Camera;
use crate::math::{add, dot, length, normalize, scale, sub, V3};
use crate::scene::{Mode, Phong, Scene, Shading};
use crate::tf::TransferFunction;
use crate::volume::{BlockGrid, Volume};

/// Volume integration stops once transmittance falls below this.
const MIN_TRANSMITTANCE: f64 = 1e-5;
/// Bisection steps refining an isosurface crossing.
const BISECTION_STEPS: usize = 40;

#[derive(Debug, Clone)]
enum Integrand {
    Volume(TransferFunction),
    Iso { value: f64, color: V3 },
}

/// The rendered image: linear RGB floats, row-major, top row first.
#[derive(Debug, Clone)]
pub struct Image {
    pub width: usize,
    pub height: usize,
    pub rgb: Vec<f32>,
}

#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
pub struct Stats {
    /// Primary rays traced (pixels x supersample^2).
    pub rays: u64,
    /// Sample positions visited along rays (including ones in skipped blocks and isosurface bisection steps).
    pub samples: u64,
}

pub struct Renderer<'a> {
    vol: &'a Volume,
    cam: Camera,
    integrand: Integrand,
    blocks: BlockGrid,
    /// Per block. Volume mode: 1 if alpha may be non-zero on the block's value range, else 0. Isosurface mode:
    /// +1 / -1 if every value in the block is above / below the iso value, 0 if the range contains it.
    block_class: Vec<i8>,
    phong: Option<Phong>,
    light: V3,
    background: V3,
    supersample: usize,
    width: usize,
    height: usize,
    /// World-space step.
    step: f64,
    skip: bool,
}

impl<'a> Renderer<'a> {
    pub fn new(scene: &Scene, vol: &'a Volume) -> Result<Renderer<'a>> {
        let cam = Camera::new(&scene.camera, scene.width, scene.height)?;
        let integrand = match scene.mode {
            Mode::Volume => {
                let tf = scene.tf.as_ref().context("mode \"volume\" requires a \"tf\" object")?;
                Integrand::Volume(TransferFunction::new(&tf.points, tf.unit_distance)?)
            }
            Mode::Isosurface => {
                let iso = scene.iso.as_ref().context("mode \"isosurface\" requires an \"iso\" object")?;
                Integrand::Iso { value: iso.value, color: iso.color }
            }
        };
        let light = match scene.light {
            Some(l) => normalize(l).context("light must be a finite non-zero direction")?,
            None => scale(cam.forward, -1.0),
        };
        let blocks = BlockGrid::new(vol);
        let block_class = (0..blocks.len())
            .map(|b| {
                let (lo, hi) = (f64::from(blocks.min[b]), f64::from(blocks.max[b]));
                match &integrand {
                    Integrand::Volume(tf) => i8::from(tf.may_be_visible(lo, hi)),
                    Integrand::Iso { value, .. } if lo > *value => 1,
                    Integrand::Iso { value, .. } if hi < *value => -1,
                    Integrand::Iso { .. } => 0,
                }
            })
            .collect();
        let min_spacing = vol.spacing.iter().copied().fold(f64::INFINITY, f64::min);
        Ok(Renderer {
            vol,
            cam,
            integrand,
            blocks,
            block_class,
            phong: (scene.shading == Shading::Phong).then_some(scene.phong),
            light,
            background: scene.background,
            supersample: scene.supersample,
            width: scene.width,
            height: scene.height,
            step: scene.step_voxels * min_spacing,
            skip: true,
        })
    }

    /// Turns empty-space skipping on or off (results must not change).
    #[cfg(test)]
    pub fn set_skip(&mut self, skip: bool) {
        self.skip = skip;
    }

    /// Number of blocks the skip may pass over without fetching samples.
    #[cfg(test)]
    pub fn skippable_blocks(&self) -> usize {
        let volume_mode = matches!(self.integrand, Integrand::Volume(_));
        // Volume mode skips class 0 (alpha is 0 on the block); isosurface mode skips classes +1 and -1.
        self.block_class.iter().filter(|&&c| (c == 0) == volume_mode).count()
    }

    /// Renders the whole image.
    pub fn render(&self) -> (Image, Stats) {
        let (w, h, s) = (self.width, self.height, self.supersample);
        let mut rgb = vec![0.0f32; w * h * 3];
        let stats = rgb
            .par_chunks_mut(w * 3)
            .enumerate()
            .map(|(y, row)| {
                let mut samples = 0u64;
                for x in 0..w {
                    let mut sum = [0.0f64; 3];
                    for b in 0..s {
                        for a in 0..s {
                            let px = x as f64 + (a as f64 + 0.5) / s as f64;
                            let py = y as f64 + (b as f64 + 0.5) / s as f64;
                            sum = add(sum, self.trace(self.cam.direction(px, py), &mut samples));
                        }
                    }
                    let n = (s * s) as f64;
                    for c in 0..3 {
                        row[3 * x + c] = (sum[c] / n) as f32;
                    }
                }
                Stats { rays: (w * s * s) as u64, samples }
            })
            .reduce(Stats::default, |a, b| Stats { rays: a.rays + b.rays, samples: a.samples + b.samples });
        (Image { width: w, height: h, rgb }, stats)
    }

    /// Colour of one ray from the eye along unit direction `d`, composited over the background.
    pub fn trace(&self, d: V3, samples: &mut u64) -> V3 {
        match &self.integrand {
            Integrand::Volume(tf) => self.trace_volume(tf, d, samples),
            Integrand::Iso { value, color } => match self.iso_hit(*value, d, samples) {
                None => self.background,
                Some(t) => {
                    let l = self.vol.locate(add(self.cam.eye, scale(d, t)));
                    let c = self.vol.corners(l.cell);
                    self.shade(*color, &c, l.frac, d)
                }
            },
        }
    }

    /// Ray parameter of the isosurface hit through sub-pixel position `(px, py)`, if any (isosurface mode).
    #[cfg(test)]
    pub fn iso_hit_at(&self, px: f64, py: f64) -> Option<f64> {
        match &self.integrand {
            Integrand::Iso { value, .. } => self.iso_hit(*value, self.cam.direction(px, py), &mut 0),
            Integrand::Volume(_) => None,
        }
    }

    /// Parametric range `[t0, t1]` (with `t0 >= 0`) of the ray inside the volume's box, if non-empty.
    fn clip(&self, d: V3) -> Option<(f64, f64)> {
        let (lo, hi, o) = (self.vol.box_min(), self.vol.box_max(), self.cam.eye);
        let (mut t0, mut t1) = (0.0f64, f64::INFINITY);
        for a in 0..3 {
            if d[a] == 0.0 {
                if o[a] < lo[a] || o[a] > hi[a] {
                    return None;
                }
            } else {
                let (ta, tb) = ((lo[a] - o[a]) / d[a], (hi[a] - o[a]) / d[a]);
                t0 = t0.max(ta.min(tb));
                t1 = t1.min(ta.max(tb));
            }
        }
        (t1 > t0).then_some((t0, t1))
    }

    fn trace_volume(&self, tf: &TransferFunction, d: V3, samples: &mut u64) -> V3 {
        let Some((t0, t1)) = self.clip(d) else {
            return self.background;
        };
        let half = self.half_vector(d);
        let n = ((t1 - t0) / self.step).ceil() as usize;
        let mut color = [0.0f64; 3];
        let mut trans = 1.0f64;
        for k in 0..n {
            let a = t0 + k as f64 * self.step;
            let b = (t0 + (k + 1) as f64 * self.step).min(t1);
            let len = b - a;
            if len <= 0.0 {
                break;
            }
            *samples += 1;
            let l = self.vol.locate(add(self.cam.eye, scale(d, 0.5 * (a + b))));
            if self.skip && self.block_class[self.blocks.index(l.cell)] == 0 {
                continue; // alpha is exactly 0 everywhere in this block: the sample would change nothing.
            }
            let c = self.vol.corners(l.cell);
            let v = Volume::value_of(&c, l.frac);
            let rgba = tf.rgba(v);
            let alpha_step = 1.0 - (-tf.sigma_from_alpha(rgba[3]) * len).exp();
            if alpha_step > 0.0 {
                let shaded = self.shade_with([rgba[0], rgba[1], rgba[2]], &c, l.frac, half);
                color = add(color, scale(shaded, trans * alpha_step));
                trans *= 1.0 - alpha_step;
                if trans < MIN_TRANSMITTANCE {
                    break;
                }
            }
        }
        add(color, scale(self.background, trans))
    }

    /// Sign of `f - iso` at ray parameter `t` (0 on an exact hit), using the block table when allowed.
    #[inline]
    fn iso_sign(&self, iso: f64, d: V3, t: f64, samples: &mut u64) -> i8 {
        *samples += 1;
        let l = self.vol.locate(add(self.cam.eye, scale(d, t)));
        if self.skip {
            let class = self.block_class[self.blocks.index(l.cell)];
            if class != 0 {
                return class; // every value in the block is strictly on this side of iso
            }
        }
        let g = Volume::value_of(&self.vol.corners(l.cell), l.frac) - iso;
        if g > 0.0 {
            1
        } else if g < 0.0 {
            -1
        } else {
            0
        }
    }

    /// First crossing of `f - iso` along the ray: samples at `t0, t0 + step, ..., t1`, then bisection.
    fn iso_hit(&self, iso: f64, d: V3, samples: &mut u64) -> Option<f64> {
        let (t0, t1) = self.clip(d)?;
        let n = ((t1 - t0) / self.step).ceil() as usize;
        let mut t_prev = t0;
        let mut s_prev = self.iso_sign(iso, d, t0, samples);
        if s_prev == 0 {
            return Some(t0);
        }
        for k in 1..=n {
            let t = if k == n { t1 } else { (t0 + k as f64 * self.step).min(t1) };
            let s = self.iso_sign(iso, d, t, samples);
            if s == 0 {
                return Some(t);
            }
            if s != s_prev {
                let (mut a, mut b) = (t_prev, t);
                for _ in 0..BISECTION_STEPS {
                    let m = 0.5 * (a + b);
                    let sm = self.iso_sign(iso, d, m, samples);
                    if sm == 0 {
                        return Some(m);
                    }
                    if sm == s_prev {
                        a = m;
                    } else {
                        b = m;
                    }
                }
                return Some(0.5 * (a + b));
            }
            t_prev = t;
            s_prev = s;
        }
        None
    }

    /// Normalised `L + V` for a ray with direction `d` (`None` if light and view are exactly opposite).
    fn half_vector(&self, d: V3) -> Option<V3> {
        normalize(sub(self.light, d))
    }

    /// Colour `c` shaded at a point given by its cell corners and cell-local coordinates (no-op without Phong).
    fn shade(&self, c: V3, corners: &[f64; 8], frac: V3, d: V3) -> V3 {
        if self.phong.is_none() {
            return c;
        }
        self.shade_with(c, corners, frac, self.half_vector(d))
    }

    /// Two-sided Phong: `c (ambient + diffuse |N.L|) + specular |N.H|^shininess`, with `N = -grad / |grad|`.
    fn shade_with(&self, c: V3, corners: &[f64; 8], frac: V3, half: Option<V3>) -> V3 {
        let Some(p) = self.phong else {
            return c;
        };
        let g = self.vol.gradient_of(corners, frac);
        let gl = length(g);
        if gl < 1e-6 {
            return scale(c, p.ambient + p.diffuse);
        }
        let n = scale(g, -1.0 / gl);
        let diffuse = dot(n, self.light).abs();
        let specular = match half {
            Some(h) => p.specular * dot(n, h).abs().powf(p.shininess),
            None => 0.0,
        };
        let k = p.ambient + p.diffuse * diffuse;
        [c[0] * k + specular, c[1] * k + specular, c[2] * k + specular]
    }
}
